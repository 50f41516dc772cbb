"""The ``printeps`` CLI: validate (compiler-style errors), deploy and fire against a live gateway,
fire locally. Runs the Typer app in-process (one JVM per test session)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gateway.cli import app

runner = CliRunner()


def run(*args: str, env: dict[str, str] | None = None):
    return runner.invoke(app, list(args), env=env or {}, catch_exceptions=False)


@pytest.fixture(scope="module")
def facts_file(cli_home: Path) -> Path:
    path = cli_home / "facts.json"
    path.write_text(json.dumps({"facts": [{"type": "Customer", "id": "c1", "age": 40}]}))
    return path


def test_validate_ok_and_errors(cli_home: Path):
    config = str(cli_home / "printeps.yaml")
    ok = run("rules", "validate", str(cli_home / "rules" / "greet"), "--config", config)
    assert ok.exit_code == 0, ok.output
    assert "ok (2 files)" in ok.output
    bad = run("rules", "validate", str(cli_home / "broken" / "bad"), "--config", config)
    assert bad.exit_code == 1
    line = bad.output.strip().splitlines()[0]
    path, lineno, col, message = line.split(":", 3)
    assert path == str(cli_home / "broken" / "bad" / "greet.drl")
    assert int(lineno) > 0 and col.isdigit() and message.strip()
    missing = run("rules", "validate", str(cli_home / "nothing-here"), "--config", config)
    assert missing.exit_code == 2 and "no such file" in missing.output


def test_deploy_and_fire_against_server(cli_home: Path, server, facts_file: Path):
    folder = str(cli_home / "rules" / "greet")
    denied = run("rules", "deploy", folder, "--server", server.url, "--token", "cli-caller")
    assert denied.exit_code == 1 and "403" in denied.output
    done = run("rules", "deploy", folder, "--server", server.url, "--token", "cli-author", "--comment", "from cli")
    assert done.exit_code == 0, done.output
    assert "deployed greet version 1" in done.output
    broken = run("rules", "deploy", str(cli_home / "broken" / "bad"), "--server", server.url,
                 "--token", "cli-author", "--name", "greet")
    assert broken.exit_code == 1 and f"{cli_home / 'broken' / 'bad' / 'greet.drl'}:" in broken.output
    fired = run("fire", "greet", str(facts_file), "--server", server.url, env={"PRINTEPS_TOKEN": "cli-caller"})
    assert fired.exit_code == 0, fired.output
    body = json.loads(fired.output)
    assert body["version"] == 1 and body["actions"][0]["params"]["text"] == "Welcome c1 (cli)"


def test_fire_locally(cli_home: Path, facts_file: Path):
    result = run("fire", "greet", str(facts_file), "--config", str(cli_home / "printeps.yaml"))
    assert result.exit_code == 0, result.output
    body = json.loads(result.output[result.output.index("{"):])
    assert body["ruleset"] == "greet" and body["actions"][0]["params"]["text"] == "Welcome c1 (cli)"
    bad = cli_home / "bad-facts.json"
    bad.write_text('{"facts": [1,]}')
    result = run("fire", "greet", str(bad), "--config", str(cli_home / "printeps.yaml"))
    assert result.exit_code == 2 and f"{bad}:1:" in result.output


def test_build_java():
    """Compiles the helpers and names the JVM's AOT class cache it trained (or found up to date)."""
    result = run("build-java")
    assert result.exit_code == 0 and "compiled" in result.output
    cache = Path(result.output.split("AOT class cache ", 1)[1].split()[0])
    assert cache.suffix == ".aot" and cache.is_file()


def test_build_java_without_a_cache_still_succeeds(monkeypatch):
    """The cache only makes starts cheaper: a failed training run is reported, not an install failure."""
    from gateway.engine import jvm_training

    def fails(settings):
        raise jvm_training.TrainingError("the JVM cache's training run failed (exit 1): boom")

    monkeypatch.setattr(jvm_training, "build", fails)
    result = run("build-java")
    assert result.exit_code == 0
    assert "no AOT class cache: the JVM cache's training run failed (exit 1): boom" in result.output
