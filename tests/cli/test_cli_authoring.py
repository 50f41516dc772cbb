"""``printeps rules test`` (locally and against a gateway, JUnit XML, exit codes) and decision tables
from the command line: errors as ``path!Sheet!C7: message``, red scenarios refusing a deploy."""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gateway.cli import app
from gateway.engine.ruleset import encode_binary, write_file

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "engine"))

from authoring_samples import ROWS, TYPES, xlsx_bytes  # noqa: E402

runner = CliRunner()

SCENARIOS = """\
- name: a pair is welcomed
  given:
    - {type: Group, entrance: front, kind: pair, size: 2}
  expect:
    fired: [Greet a pair]
    actions:
      - {module: say, params: {text: "Welcome. Two seats?"}}
"""


def run(*args: str, env: dict[str, str] | None = None):
    return runner.invoke(app, list(args), env=env or {}, catch_exceptions=False)


def data_rows(**cells: str) -> list[list[str]]:
    """The sample table's rule rows (row 11 onwards) with cells changed: ``E11="Hello!"``."""
    rows = [list(r) for r in ROWS]
    for ref, value in cells.items():
        rows[int(ref[1:]) - 11][ord(ref[0]) - ord("A")] = value
    return rows


def make_folder(root: Path, name: str, rows: list[list[str]] | None = None, scenarios: str = SCENARIOS) -> Path:
    folder = root / name
    (folder / "tests").mkdir(parents=True, exist_ok=True)
    (folder / "types.drl").write_text(TYPES)
    (folder / "greetings.xlsx").write_bytes(xlsx_bytes(rows))
    (folder / "tests" / "greetings.yaml").write_text(scenarios)
    return folder


@pytest.fixture(scope="module")
def config(cli_home: Path) -> str:
    return str(cli_home / "printeps.yaml")


def test_rules_test_locally_green_red_and_junit(cli_home: Path, config: str, tmp_path: Path):
    green = make_folder(tmp_path, "greetings")
    result = run("rules", "test", str(green), "--config", config, "--junit", str(tmp_path / "green.xml"))
    assert result.exit_code == 0, result.output
    assert "  ✓ a pair is welcomed" in result.output
    assert "Rules no scenario fires (2 of 3): Greet a family, Greet anyone" in result.output
    assert result.output.strip().endswith("greetings: 1 scenarios: 1 passed — all green")
    assert ET.parse(tmp_path / "green.xml").getroot().get("tests") == "1"

    red = make_folder(tmp_path, "red", data_rows(E11="Hello!"))
    result = run("rules", "test", str(red), "--config", config, "--junit", str(tmp_path / "red.xml"))
    assert result.exit_code == 1
    assert f"{red}/tests/greetings.yaml:7: expected action say" in result.output
    assert "actual: fired Greet a pair" in result.output
    failure = ET.parse(tmp_path / "red.xml").getroot().find("testsuite/testcase/failure")
    assert failure is not None and "was not requested" in failure.get("message")


def test_rules_test_reports_malformed_scenarios_and_table_cells(cli_home: Path, config: str, tmp_path: Path):
    bad = make_folder(tmp_path, "bad", scenarios="- name: x\n  expect:\n    fired: {X: many}\n")
    result = run("rules", "test", str(bad), "--config", config)
    assert result.exit_code == 1
    assert f"{bad}/tests/greetings.yaml:3:16: 'fired': the count for 'X' must be a whole number" in result.output
    cell = make_folder(tmp_path, "cell", data_rows(F11="high"))
    result = run("rules", "validate", str(cell), "--config", config)
    assert result.exit_code == 1
    assert f"{cell}/greetings.xlsx!Greetings!F11: PRIORITY must be a whole number, not 'high'" in result.output
    assert run("rules", "test", "--config", config).exit_code == 2  # no folder, no server


def test_rules_test_on_a_server_and_the_deploy_gate(cli_home: Path, server, tmp_path: Path):
    folder = make_folder(tmp_path, "served")
    env = {"PRINTEPS_TOKEN": "cli-author"}
    done = run("rules", "deploy", str(folder), "--server", server.url, env=env)
    assert done.exit_code == 0, done.output
    deployed = run("rules", "test", "--server", server.url, "--ruleset", "served", "--junit", str(tmp_path / "s.xml"),
                   env={"PRINTEPS_TOKEN": "cli-caller"})
    assert deployed.exit_code == 0, deployed.output
    assert "served version 1: 1 scenarios: 1 passed — all green" in deployed.output
    assert (tmp_path / "s.xml").exists()

    # The folder, changed, tested on the server as a draft; then its deploy is refused until forced.
    write_file(folder / "greetings.xlsx", encode_binary(xlsx_bytes(data_rows(E11="Hello!"))))
    draft = run("rules", "test", str(folder), "--server", server.url, env=env)
    assert draft.exit_code == 1 and "✗ a pair is welcomed" in draft.output
    refused = run("rules", "deploy", str(folder), "--server", server.url, env=env)
    assert refused.exit_code == 1
    assert f"{folder}/tests/greetings.yaml:7:1: scenario 'a pair is welcomed': expected action say" in refused.output
    assert "not deployed: 1 of 1 scenarios are red" in refused.output
    assert "deploy with --force" in refused.output and '"force": true' not in refused.output  # the CLI's own flag
    forced = run("rules", "deploy", str(folder), "--server", server.url, "--force", env=env)
    assert forced.exit_code == 0 and "deployed served version 2" in forced.output
    stale = run("rules", "deploy", str(folder), "--server", server.url, "--force", "--base-version", "1", env=env)
    assert stale.exit_code == 1 and "the current version is 2, not 1" in stale.output, stale.output
    missing = run("rules", "test", "--server", server.url, "--ruleset", "nothing-here", env=env)
    assert missing.exit_code == 1 and "404" in missing.output
