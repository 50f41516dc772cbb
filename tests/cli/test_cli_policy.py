"""Open mode stays on the machine, and ``rules validate/test --role author`` apply the rule policy
(issue 26). The refusal runs the Typer app in-process (it exits before building anything); the
forced open mode starts a real ``printeps serve`` process."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest
import yaml
from typer.testing import CliRunner

from gateway.cli import app
from gateway.config import ApiSettings
from gateway.serve import free_port, open_mode_check
from gw_testing import short_lived_jvm

PROJECT = Path(__file__).resolve().parents[2]
runner = CliRunner()

PROBE = """package org.printeps.clipolicy;
declare Customer
    id : String
end
rule "leak"
when
    $c : Customer()
then
    System.out.println("hello from " + $c.getId());
end
"""


def _no_auth_env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items()
            if k not in ("PRINTEPS_TOKENS", "PRINTEPS_BASIC_USERS", "PRINTEPS_API_OPEN", "MONGO_URI")}


@pytest.fixture()
def config(tmp_path: Path) -> Path:
    path = tmp_path / "printeps.yaml"
    path.write_text(yaml.safe_dump({"data_dir": str(tmp_path / "var"), "streams": {"queries_dir": None}}))
    return path


def test_open_mode_is_for_loopback_addresses_only():
    open_api, forced, secured = ApiSettings(), ApiSettings(open=True), ApiSettings(tokens="t:author:a")
    for host in ("127.0.0.1", "127.0.0.2", "::1", "[::1]", "localhost"):
        assert open_mode_check(open_api, host) == (None, None), host
    for host in ("0.0.0.0", "::", "", "192.168.1.20", "gateway.example"):
        refusal, warning = open_mode_check(open_api, host)
        assert refusal and "PRINTEPS_TOKENS" in refusal and "PRINTEPS_API_OPEN=1" in refusal and warning is None
        assert open_mode_check(secured, host) == (None, None)
        refusal, warning = open_mode_check(forced, host)
        assert refusal is None and "WARNING" in warning and "run code" in warning


def test_serve_refuses_a_public_address_without_tokens(config: Path, monkeypatch):
    for var in ("PRINTEPS_TOKENS", "PRINTEPS_BASIC_USERS", "PRINTEPS_API_OPEN"):
        monkeypatch.delenv(var, raising=False)
    started = time.monotonic()
    result = runner.invoke(app, ["serve", "--host", "0.0.0.0", "--no-ros", "--config", str(config)])
    assert result.exit_code == 2, result.output
    assert "refusing to listen on 0.0.0.0" in result.output and "PRINTEPS_TOKENS" in result.output
    assert "PRINTEPS_API_OPEN=1" in result.output
    assert time.monotonic() - started < 10  # refused before any gateway was built
    assert not (config.parent / "var").exists()


def test_forced_open_mode_starts_on_a_public_address_and_warns(config: Path, tmp_path: Path):
    port = free_port()
    stderr = tmp_path / "stderr.txt"
    with stderr.open("w") as err:
        serve = subprocess.Popen([sys.executable, "-m", "gateway.cli", "serve", "--no-ros", "--host", "0.0.0.0",
                                  "--port", str(port), "--config", str(config)],
                                 env=short_lived_jvm({**_no_auth_env(), "PRINTEPS_API_OPEN": "1"}), cwd=PROJECT,
                                 stdout=subprocess.DEVNULL, stderr=err)
    try:
        deadline = time.monotonic() + 180
        while True:
            assert serve.poll() is None, stderr.read_text()[-3000:]
            assert time.monotonic() < deadline, "printeps serve did not start"
            try:
                if httpx.get(f"http://127.0.0.1:{port}/health", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.3)
        who = httpx.get(f"http://127.0.0.1:{port}/api/whoami", timeout=10).json()
        assert who == {"name": "anonymous", "role": "developer", "auth": "open"}
    finally:
        serve.terminate()
        serve.wait(timeout=60)
    assert "WARNING: the REST API is open (no authentication) on 0.0.0.0" in stderr.read_text()


def test_rules_validate_and_test_as_an_author_apply_the_policy(tmp_path: Path):
    folder = tmp_path / "leaky"
    folder.mkdir()
    (folder / "rules.drl").write_text(PROBE)
    as_author = runner.invoke(app, ["rules", "validate", str(folder), "--role", "author"])
    assert as_author.exit_code == 1
    assert f"{folder / 'rules.drl'}:9:5: rule policy: class 'java.lang.System'" in as_author.output
    assert runner.invoke(app, ["rules", "validate", str(folder)]).exit_code == 0  # a developer's local check
    tested = runner.invoke(app, ["rules", "test", str(folder), "--role", "author"])
    assert tested.exit_code == 1 and "java.lang.System" in tested.output
    assert runner.invoke(app, ["rules", "validate", str(folder), "--role", "boss"]).exit_code == 2
