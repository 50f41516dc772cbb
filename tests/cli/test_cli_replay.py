"""``printeps rules replay``: the CI gate over a live gateway (real HTTP, real JVM and database).
Exit codes: 0 when nothing changed or without --fail-on-change, 1 when something changed with
--fail-on-change or the candidate does not compile."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import httpx
from typer.testing import CliRunner

from gateway.cli import app

from api_helpers import BROKEN, files

runner = CliRunner()
AUTHOR = {"Authorization": "Bearer cli-author"}


def run(*args: str):
    return runner.invoke(app, list(args), env={"PRINTEPS_TOKEN": "cli-author"}, catch_exceptions=False)


def folder(root: Path, name: str, content: dict[str, str]) -> Path:
    path = root / name
    path.mkdir(parents=True, exist_ok=True)
    for fname, text in content.items():
        (path / fname).write_text(text)
    return path


def test_replay_gate_exit_codes_table_and_junit(tmp_path: Path, server):
    name = "replayed"
    deployed = httpx.put(f"{server.url}/api/rulesets/{name}", json={"files": files("v1")}, headers=AUTHOR)
    assert deployed.status_code == 201, deployed.text
    adult, child = {"type": "Customer", "id": "c1", "age": 34}, {"type": "Customer", "id": "c2", "age": 7}
    for facts in ([adult], [child], [adult, child]):
        fired = httpx.post(f"{server.url}/api/rulesets/{name}/fire", json={"facts": facts}, headers=AUTHOR)
        assert fired.status_code == 200, fired.text

    same = run("rules", "replay", str(folder(tmp_path / "same", name, files("v1"))), "--server", server.url,
               "--fail-on-change")
    assert same.exit_code == 0, same.output
    assert "replayed 3 decisions" in same.output and "0 changed" in same.output

    edited = folder(tmp_path / "edited", name, files("v2"))
    report = tmp_path / "replay.xml"
    told = run("rules", "replay", str(edited), "--server", server.url, "--junit", str(report))
    assert told.exit_code == 0, told.output
    assert "2 changed, 1 unchanged" in told.output
    table = [line.split() for line in told.output.splitlines() if line.startswith(("Adult", "Greet adult"))]
    assert ["Adult", "2", "2"] in table and ["Greet", "adult", "2", "2"] in table
    cases = ET.parse(report).getroot().iter("testcase")
    assert len([c for c in cases if c.find("failure") is not None]) == 0

    gated = run("rules", "replay", str(edited), "--server", server.url, "--fail-on-change", "--junit", str(report))
    assert gated.exit_code == 1, gated.output
    failures = [c for c in ET.parse(report).getroot().iter("testcase") if c.find("failure") is not None]
    assert len(failures) == 2 and "(v2)" in failures[0].find("failure").text

    broken = run("rules", "replay", str(folder(tmp_path / "broken", name, BROKEN)), "--server", server.url)
    assert broken.exit_code == 1 and f"{tmp_path / 'broken' / name / 'greet.drl'}:" in broken.output
    limited = run("rules", "replay", str(edited), "--server", server.url, "--limit", "1")
    assert limited.exit_code == 0 and "replayed 1 decisions" in limited.output and "newest 1" in limited.output
