"""``printeps``: run the gateway, check and deploy rule sets, fire rules (Typer).

Why these commands: rule authors work on folders of ``.drl``/``.dslr`` files; ``rules validate``
gives compiler-style ``file:line:col: message`` lines (usable from editors and CI), ``rules deploy``
ships a folder to a running gateway, ``fire`` answers "what would the rules do with these facts"
locally or against a server.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any, Optional

import typer

app = typer.Typer(help="PRINTEPS gateway: a Drools-backed rules server for service robots.", no_args_is_help=True)
rules_app = typer.Typer(help="Check and deploy rule sets (folders of .drl/.dsl/.dslr files).", no_args_is_help=True)
app.add_typer(rules_app, name="rules")

DEFAULT_SERVER = "http://127.0.0.1:8080"
ConfigOption = typer.Option(None, "--config", "-c", help="Settings YAML (default: $PRINTEPS_CONFIG).")


def _settings(config: Optional[Path]):
    from gateway.config import load_settings

    try:
        return load_settings(config)
    except (OSError, ValueError) as exc:
        _fail(f"{config or os.environ.get('PRINTEPS_CONFIG')}: {exc}", code=2)


def _fail(message: str, code: int = 1) -> None:
    typer.echo(message, err=True)
    raise typer.Exit(code)


def _server(server: Optional[str]) -> str:
    return (server or os.environ.get("PRINTEPS_SERVER") or DEFAULT_SERVER).rstrip("/")


def _headers(token: Optional[str]) -> dict[str, str]:
    token = token or os.environ.get("PRINTEPS_TOKEN")
    return {"Authorization": f"Bearer {token}"} if token else {}


def read_ruleset(path: Path) -> tuple[str, dict[str, str]]:
    """(name, files) of a rule set folder, or of a single rule file (name = its stem)."""
    from gateway.engine.ruleset import is_rule_file, read_folder

    if path.is_dir():
        return path.name, read_folder(path)
    if path.is_file():
        if not is_rule_file(path.name):
            _fail(f"{path}: not a rule file (.drl, .dsl, .dslr)", code=2)
        return path.stem, {path.name: path.read_text(encoding="utf-8")}
    _fail(f"{path}: no such file or folder", code=2)
    raise AssertionError  # unreachable


def format_errors(errors: list[dict[str, Any]], folder: Path | None) -> list[str]:
    """Compiler-style lines ``path:line:col: message`` (path relative to where the files live)."""
    lines = []
    for e in errors:
        fname = e.get("file") or ""
        where = str(folder / fname) if folder is not None and fname else (fname or "<rule set>")
        lines.append(f"{where}:{e.get('line', 0)}:{e.get('column', 0)}: {e.get('message', '')}")
    return lines


def _read_facts(path: Path) -> list[dict[str, Any]]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        _fail(f"{path}: {exc.strerror}", code=2)
    except json.JSONDecodeError as exc:
        _fail(f"{path}:{exc.lineno}:{exc.colno}: {exc.msg}", code=2)
    facts = data.get("facts") if isinstance(data, dict) else data
    if not isinstance(facts, list):
        _fail(f"{path}: expected a list of facts or {{\"facts\": [...]}}", code=2)
    return facts


def _print_json(value: Any) -> None:
    typer.echo(json.dumps(value, indent=2, ensure_ascii=False, default=str))


@app.command()
def serve(
    host: Optional[str] = typer.Option(None, help="Listen address (default: settings.api.host, 127.0.0.1)."),
    port: Optional[int] = typer.Option(None, help="Listen port (default: settings.api.port, 8080)."),
    config: Optional[Path] = ConfigOption,
    load_rules: bool = typer.Option(True, help="Deploy rules/drl/* (settings.engine.rules_dir) at start."),
) -> None:
    """Run the gateway (REST API, KIE Server compatible API, /docs) with uvicorn."""
    import gc

    import uvicorn

    from gateway.server import build_gateway

    settings = _settings(config)
    gateway = build_gateway(settings, load_rules=load_rules)
    gc.collect()
    gc.freeze()  # startup objects (JPype, FastAPI, Drools proxies) leave the GC's scans: shorter pauses
    try:
        uvicorn.run(
            gateway.app,
            host=host or settings.api.host,
            port=port or settings.api.port,
            loop="auto",
            http="auto",
            log_level="info",
            access_log=False,
        )
    finally:
        gateway.close()


@app.command()
def demo(
    headless: bool = typer.Option(False, help="Play the scenario and exit (no browser-facing gateway left running)."),
    speed: float = typer.Option(1.0, help="Replay speed of the sensor scenario (2 = twice as fast)."),
    scenario: Optional[Path] = typer.Option(None, help="Scenario file (default: scenarios/teahouse-reception.yaml)."),
    config: Optional[Path] = ConfigOption,
) -> None:
    """The teahouse reception end to end: gateway, embedded database, ROS node, sensor and Pepper
    simulators; prints what happens and a summary. Without --headless the gateway keeps running
    (workbench at http://127.0.0.1:8080/workbench) until Ctrl-C."""
    import sys as _sys

    from gateway.demo import run_demo

    _sys.setswitchinterval(0.001)  # short GIL hand-offs between the ROS executor and the worker
    summary = run_demo(_settings(config), headless=headless, scenario=scenario, speed=speed)
    if summary.get("failed"):
        raise typer.Exit(1)


@rules_app.command("validate")
def rules_validate(
    path: Path = typer.Argument(..., help="A rule set folder or a single .drl/.dslr file."),
    config: Optional[Path] = ConfigOption,
) -> None:
    """Compile locally; print ``file:line:col: message`` per problem and exit 1 if there is any."""
    from gateway.engine import Engine, EngineError

    name, files = read_ruleset(path)
    folder = path if path.is_dir() else path.parent
    engine = Engine(_settings(config))
    from gateway.progress import TerminalProgress

    progress = TerminalProgress() if sys.stderr.isatty() else None  # big sets take a while: show how far
    try:
        errors = [e.to_dict() for e in engine.validate(name, files, on_progress=progress)]
    except EngineError as exc:
        body = exc.to_dict()
        errors = body.get("errors") or [{"file": "", "line": 0, "column": 0, "message": str(exc)}]
    finally:
        if progress is not None:
            progress.close()
    if errors:
        for line in format_errors(errors, folder):
            typer.echo(line)
        raise typer.Exit(1)
    typer.echo(f"{path}: ok ({len(files)} files)")


@rules_app.command("deploy")
def rules_deploy(
    path: Path = typer.Argument(..., help="A rule set folder (its name is the rule set name)."),
    server: Optional[str] = typer.Option(None, help=f"Gateway URL (default: $PRINTEPS_SERVER or {DEFAULT_SERVER})."),
    token: Optional[str] = typer.Option(None, help="Author token (default: $PRINTEPS_TOKEN)."),
    name: Optional[str] = typer.Option(None, help="Rule set name (default: the folder name)."),
    comment: str = typer.Option("", help="Version comment."),
    base_version: Optional[int] = typer.Option(None, help="Refuse (409) if the current version is not this."),
) -> None:
    """Deploy a rule set folder to a running gateway (PUT /api/rulesets/{name})."""
    import httpx

    folder_name, files = read_ruleset(path)
    name = name or folder_name
    folder = path if path.is_dir() else path.parent
    body: dict[str, Any] = {"files": files, "comment": comment}
    if base_version is not None:
        body["base_version"] = base_version
    url = f"{_server(server)}/api/rulesets/{name}"
    try:
        response = httpx.put(url, json=body, headers=_headers(token), timeout=120)
    except httpx.HTTPError as exc:
        _fail(f"{url}: {exc}")
    data = _json_or_text(response)
    if response.status_code == 201:
        typer.echo(f"deployed {data['name']} version {data['version']}")
        return
    if response.status_code == 422 and isinstance(data, dict) and data.get("errors"):
        for line in format_errors(data["errors"], folder):
            typer.echo(line)
        raise typer.Exit(1)
    _fail(f"{url}: HTTP {response.status_code}: {data.get('error') if isinstance(data, dict) else data}")


@app.command()
def fire(
    ruleset: str = typer.Argument(..., help="Rule set name."),
    facts_file: Path = typer.Argument(..., metavar="FACTS.json", help="A JSON list of facts or {\"facts\": [...]}."),
    server: Optional[str] = typer.Option(None, help="Fire on this gateway instead of a local engine."),
    token: Optional[str] = typer.Option(None, help="Caller token (default: $PRINTEPS_TOKEN)."),
    config: Optional[Path] = ConfigOption,
) -> None:
    """Fire a rule set on facts and print the result (version, actions, fired rules, facts)."""
    facts = _read_facts(facts_file)
    if server or os.environ.get("PRINTEPS_SERVER"):
        import httpx

        url = f"{_server(server)}/api/rulesets/{ruleset}/fire"
        try:
            response = httpx.post(url, json={"facts": facts}, headers=_headers(token), timeout=60)
        except httpx.HTTPError as exc:
            _fail(f"{url}: {exc}")
        data = _json_or_text(response)
        if response.status_code != 200:
            _print_json(data)
            raise typer.Exit(1)
        _print_json(data)
        return
    from gateway.engine import Engine, EngineError

    engine = Engine(_settings(config))
    try:
        engine.load_rules_dir()
        result = engine.fire(ruleset, facts)
    except EngineError as exc:
        _print_json(exc.to_dict())
        raise typer.Exit(1)
    _print_json(result.to_dict())


@app.command("build-java")
def build_java(config: Optional[Path] = ConfigOption) -> None:
    """Start the JVM once so the Java helpers (java/src) are compiled into the cache now."""
    from gateway import jvm

    settings = _settings(config)
    try:
        jvm.start(settings.jvm)
    except jvm.JvmError as exc:
        _fail(str(exc))
    typer.echo("JVM started; Java helpers compiled")


def _json_or_text(response: Any) -> Any:
    try:
        return response.json()
    except ValueError:
        return response.text


def main() -> None:  # pragma: no cover - console entry point alternative
    app(prog_name="printeps")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
