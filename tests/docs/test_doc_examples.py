"""The docs' examples run against a real gateway, so documented behaviour is tested behaviour
(issue 32): an example that drifts from what the gateway does fails here.

Two conventions in the Markdown (README.md and docs/*.md), both announced by an HTML comment on the
line before a fenced block, invisible when rendered:

``<!-- example -->`` before an ``http`` block — a request and the answer it gets::

    POST /api/rulesets/reception/fire          request line (a path of this gateway)
    Content-Type: application/json             headers (optional; JSON is the default)
                                               blank line
    {"facts": [...]}                           body (optional; may span lines)
                                               blank line
    HTTP/1.1 422                               the status it answers
    {"kind": "facts", "errors": [{"index": 0}]}   key fields of the answer (optional)

  The key fields are a subset of the answer: an object's keys must be there with matching values;
  a list's items match the answer's first items in order (the answer may have more).
  Examples of one file run in order against one gateway seeded from the repository (they may build
  on each other: a session opened by one is used by the next).

``<!-- cli-example -->`` before an ``sh`` block — every line whose comment ends in ``→ exit N`` runs
``printeps`` with those arguments (``.venv/bin/`` dropped), from a folder where ``rules/`` is the
repository's (``workflows/`` too) and ``facts.json`` holds the documented facts; ``--server URL`` is pointed at a test
gateway and ``--token …`` dropped (it runs open). Lines without ``→ exit`` (``serve``, ``ros``: they
run until stopped) are not run.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from gateway.config import PROJECT_ROOT, Settings

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "api"))
from api_helpers import ServerThread  # noqa: E402

DOCS = [PROJECT_ROOT / "README.md", *sorted((PROJECT_ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"<!--\s*(example|cli-example)\b[^>]*-->\s*\n```(\w*)\n(.*?)\n```", re.DOTALL)
EXIT = re.compile(r"#.*→ exit (\d+)\s*$")
#: The facts ``printeps fire reception facts.json`` is documented with (README.md).
FACTS = [{"type": "Entrance", "id": "entrance", "number_of_customers": 1},
         {"type": "Customer", "id": "c1", "age": 30, "gender": "female", "entrance": "entrance"},
         {"type": "Robot", "id": "pepper", "position": "entrance"}]


@dataclass
class HttpExample:
    file: str
    line: int
    method: str
    path: str
    headers: dict[str, str] = field(default_factory=dict)
    body: bytes | None = None
    status: int = 0
    expect: Any = None

    def __str__(self) -> str:
        return f"{self.file}:{self.line}: {self.method} {self.path}"


def _blocks(kind: str) -> list[tuple[str, int, str]]:
    out = []
    for doc in DOCS:
        text = doc.read_text(encoding="utf-8")
        for match in FENCE.finditer(text):
            if match.group(1) == kind:
                out.append((str(doc.relative_to(PROJECT_ROOT)), text.count("\n", 0, match.start(3)) + 1, match.group(3)))
    return out


def parse_http(file: str, line: int, text: str) -> HttpExample:
    """One ``http`` example block (see the module docstring)."""
    request, _, answer = text.partition("\nHTTP/1.1 ")
    assert answer, f"{file}:{line}: an example needs its answer ('HTTP/1.1 <status>')"
    head, _, body = request.strip().partition("\n\n")
    first, *header_lines = head.splitlines()
    method, path = first.split(None, 1)
    headers = dict(h.split(": ", 1) for h in header_lines)
    status, _, expect = answer.partition("\n")
    return HttpExample(file, line, method, path.strip(), headers, body.strip().encode() if body.strip() else None,
                       int(status.split()[0]), json.loads(expect) if expect.strip() else None)


def matches(expected: Any, actual: Any, where: str = "") -> list[str]:
    """What of ``expected`` (key fields) ``actual`` lacks: [] when it holds them all."""
    if isinstance(expected, dict):
        if not isinstance(actual, dict):
            return [f"{where or 'answer'}: expected an object, got {actual!r}"]
        out = []
        for key, value in expected.items():
            if key not in actual:
                out.append(f"{where}.{key}: missing")
            else:
                out += matches(value, actual[key], f"{where}.{key}")
        return out
    if isinstance(expected, list):
        if not isinstance(actual, list) or len(actual) < len(expected):
            return [f"{where}: expected at least {len(expected)} items, got {actual!r}"]
        return [m for k, item in enumerate(expected) for m in matches(item, actual[k], f"{where}[{k}]")]
    return [] if expected == actual else [f"{where}: expected {expected!r}, got {actual!r}"]


HTTP_EXAMPLES = [parse_http(*block) for block in _blocks("example")]


def test_the_docs_have_examples_in_every_family():
    """The convention is used: the examples cover fire, sessions, management, KIE and the error table."""
    paths = " ".join(e.path for e in HTTP_EXAMPLES)
    for family in ("/fire", "/sessions", "/validate", "/kie-server/", "/api/decisions", "/api/workflows", "/api/streams",
                   "/api/knowledge"):
        assert family in paths, family
    assert {e.status for e in HTTP_EXAMPLES} >= {200, 201, 400, 404, 409, 415, 422}


@pytest.fixture(scope="module")
def gateway(tmp_path_factory, mongo):
    from gw_testing import built_gateway

    tmp = tmp_path_factory.mktemp("docs")
    settings = Settings.model_validate({"data_dir": str(tmp / "var"),
                                        "workflows": {"simulate_robots": True, "simulate_humans": True}})
    with built_gateway(settings, mongo, tmp) as gw:
        yield gw


@pytest.fixture(scope="module")
def client(gateway):
    with TestClient(gateway.app) as c:
        yield c


@pytest.mark.parametrize("doc", sorted({e.file for e in HTTP_EXAMPLES}))
def test_the_http_examples_of_a_doc_answer_as_documented(client, doc):
    failures = []
    for example in (e for e in HTTP_EXAMPLES if e.file == doc):
        headers = {"Content-Type": "application/json", **example.headers} if example.body is not None else example.headers
        r = client.request(example.method, example.path, content=example.body, headers=headers)
        try:
            answer = r.json()
        except ValueError:
            answer = r.text
        problems = [] if r.status_code == example.status else [f"status {r.status_code}, documented {example.status}"]
        if example.expect is not None:
            problems += matches(example.expect, answer)
        if problems:
            failures.append(f"{example}: {'; '.join(problems)}\n    answer: {json.dumps(answer)[:600]}")
    assert not failures, "\n".join(failures)


CLI_LINES = [(file, line + k, raw) for file, line, text in _blocks("cli-example")
             for k, raw in enumerate(text.splitlines()) if EXIT.search(raw)]


def test_the_docs_have_cli_examples():
    assert len(CLI_LINES) >= 4


@pytest.fixture(scope="module")
def server(gateway):
    running = ServerThread(gateway.app).start()
    yield running
    running.stop()


@pytest.mark.parametrize("file,line,raw", CLI_LINES, ids=[f"{f}:{n}" for f, n, _ in CLI_LINES])
def test_a_cli_example_exits_as_documented(file, line, raw, server, tmp_path):
    expected = int(EXIT.search(raw).group(1))
    command = raw.split("#", 1)[0].strip().split()
    assert command[0].endswith("printeps"), f"{file}:{line}: a CLI example runs printeps"
    args = []
    skip = False
    for k, arg in enumerate(command[1:]):
        if skip:
            skip = False
            continue
        if arg == "--token":
            skip = True
            continue
        args.append(server.url if k > 0 and command[k] == "--server" else arg)
    for folder in ("rules", "workflows"):
        (tmp_path / folder).symlink_to(PROJECT_ROOT / folder)
    (tmp_path / "facts.json").write_text(json.dumps(FACTS))
    env = {**os.environ, "PYTHONPATH": os.environ.get("PYTHONPATH", str(PROJECT_ROOT))}
    env.pop("PRINTEPS_SERVER", None)
    done = subprocess.run([sys.executable, "-m", "gateway.cli", *args], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == expected, f"{file}:{line}: {raw}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"


def test_the_documented_scenario_report_is_the_one_the_gateway_gives(client):
    """docs/rest-api.md's test report: the pair scenario at line 191 of tests/reception.yaml fails at
    the line of its expected action (it said 199, the line is 200) when the greeting changes."""
    from gateway.engine.ruleset import read_folder

    text = (PROJECT_ROOT / "docs" / "rest-api.md").read_text(encoding="utf-8")
    scenario_line, failure_line = map(int, re.search(
        r'"name": "pair: the papers\' greeting", "file": "tests/reception.yaml", "line": (\d+),.*?"failures": \[\{"line": (\d+)',
        text, re.DOTALL).groups())
    files = read_folder(PROJECT_ROOT / "rules" / "drl" / "reception")
    files["reception.dslr"] = files["reception.dslr"].replace("Welcome. Two seats?", "Hi!")
    assert files["reception.dslr"] != read_folder(PROJECT_ROOT / "rules" / "drl" / "reception")["reception.dslr"]
    report = client.post("/api/rulesets/reception/test", json={"files": files}).json()
    pair = next(r for r in report["results"] if r["name"] == "pair: the papers' greeting")
    assert (pair["line"], pair["status"], pair["failures"][0]["line"]) == (scenario_line, "failed", failure_line)
    assert 'expected action say {robot: pepper, text: "Welcome. Two seats?"} was not requested' in pair["failures"][0]["message"]
