"""``printeps``: run the gateway, check and deploy rule sets, fire rules (Typer).

Why these commands: rule authors work on folders of ``.drl``/``.dslr`` files; ``rules validate``
gives compiler-style ``file:line:col: message`` lines (usable from editors and CI), ``rules deploy``
ships a folder to a running gateway, ``fire`` answers "what would the rules do with these facts"
locally or against a server.
"""

from __future__ import annotations

import json
import logging
import os
import sys
from pathlib import Path
from typing import Any, Optional

import typer

app = typer.Typer(help="PRINTEPS gateway: a Drools-backed rules server for service robots.", no_args_is_help=True)
rules_app = typer.Typer(help="Check and deploy rule sets (folders of .drl/.dsl/.dslr files).", no_args_is_help=True)
app.add_typer(rules_app, name="rules")
workflow_app = typer.Typer(help="Check workflow files and generate their standalone ROS nodes.", no_args_is_help=True)
app.add_typer(workflow_app, name="workflow")

DEFAULT_SERVER = "http://127.0.0.1:8080"
ConfigOption = typer.Option(None, "--config", "-c", help="Settings YAML (default: $PRINTEPS_CONFIG).")
def _role(value: str) -> str:
    if value not in ("developer", "author"):
        raise typer.BadParameter("use 'developer' or 'author'")
    return value


RoleOption = typer.Option("developer", "--role", callback=_role,
                          help="Check as this role: 'author' also applies the rule policy, as a gateway does "
                               "for an author's deploy (a local run is a developer's).")


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
    from gateway.engine.ruleset import is_rule_file, read_file, read_folder

    if path.is_dir():
        return path.name, read_folder(path)
    if path.is_file():
        if not is_rule_file(path.name):
            _fail(f"{path}: not a rule file (.drl, .dsl, .dslr, .csv, .xlsx)", code=2)
        return path.stem, {path.name: read_file(path)}
    _fail(f"{path}: no such file or folder", code=2)
    raise AssertionError  # unreachable


def format_errors(errors: list[dict[str, Any]], folder: Path | None) -> list[str]:
    """Compiler-style lines ``path:line:col: message`` (path relative to where the files live)."""
    lines = []
    for e in errors:
        fname = e.get("file") or ""
        where = str(folder / fname) if folder is not None and fname else (fname or "<rule set>")
        if e.get("cell"):  # a decision table: file!Sheet!C7
            lines.append(f"{where}!{e.get('sheet')}!{e['cell']}: {e.get('message', '')}")
            continue
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
    workers: int = typer.Option(1, min=1, max=64, help="Worker processes on one port, each a full gateway member."),
    ros: Optional[bool] = typer.Option(None, "--ros/--no-ros",
                                       help="Run the ROS node (default: when rclpy is importable; worker 0 only)."),
    config: Optional[Path] = ConfigOption,
) -> None:
    """Run the gateway: REST API, KIE Server compatible API, workbench, stream engine and the ROS
    node, over the Information State (MONGO_URI, or the embedded database)."""
    settings = _settings(config)
    _keep_open_mode_local(settings, host or settings.api.host)
    if workers > 1:
        from gateway.serve import Supervisor, config_path

        supervisor = Supervisor(workers, host or settings.api.host, port or settings.api.port,
                                config=config_path(config), ros=ros)
        raise typer.Exit(supervisor.run(settings))
    from gateway.serve import run

    sys.setswitchinterval(0.001)  # GIL hand-offs between the ROS executor and the workers: see docs/ros.md
    _run_or_explain(lambda: run(settings, rest=True, ros=ros, host=host, port=port))


@app.command("ros", context_settings={"allow_extra_args": True, "ignore_unknown_options": True})
def ros_node(
    ctx: typer.Context,
    rest: bool = typer.Option(False, "--rest/--no-rest", help="Also serve the REST API and workbench."),
    port: Optional[int] = typer.Option(None, help="Listen port with --rest (default: settings.api.port)."),
    config: Optional[Path] = ConfigOption,
) -> None:
    """The ROS launcher (no `ros2 launch` here): the gateway with its ROS node, until Ctrl-C.

    Arguments after ``--ros-args`` go to the node as on ``ros2 run``, e.g. ``printeps ros --ros-args
    -p call_timeout_s:=3.0 -p robots:="[pepper=/pepper]"``."""
    from gateway.serve import run

    settings = _settings(config)
    settings.ros.args = ros_arguments(ctx.args)
    if rest:
        _keep_open_mode_local(settings, settings.api.host)
    sys.setswitchinterval(0.001)
    _run_or_explain(lambda: run(settings, rest=rest, ros=True, port=port))


def ros_arguments(extra: list[str]) -> list[str]:
    """The ROS part of the command line: ``--ros-args`` and what follows; anything else is a usage error."""
    if not extra:
        return []
    if extra[0] != "--ros-args":
        _fail(f"printeps ros: unexpected argument {extra[0]!r} (ROS arguments go after --ros-args)", code=2)
    return list(extra)


def _keep_open_mode_local(settings: Any, host: str) -> None:
    """Open mode (no tokens) listens on this machine only: exit 2 saying how to configure tokens,
    or warn at every start when PRINTEPS_API_OPEN=1 forces it (see gateway.serve.open_mode_check)."""
    from gateway.serve import open_mode_check

    refusal, warning = open_mode_check(settings.api, host)
    if refusal:
        _fail(refusal, code=2)
    if warning:
        typer.echo(warning, err=True)


def _run_or_explain(start: Any) -> None:
    """Run; a gateway that cannot start (database held by another process, …) says why, no traceback."""
    from gateway.store.embedded import EmbeddedDbError
    from gateway.store.store import StoreUnavailable
    from gateway.base.versions import CatalogUnavailable

    try:
        start()
    except (EmbeddedDbError, StoreUnavailable, CatalogUnavailable) as exc:
        _fail(f"printeps: cannot start: {exc}", code=3)


@app.command()
def demo(
    headless: bool = typer.Option(False, help="Play the scenario and exit (no browser-facing gateway left running)."),
    speed: float = typer.Option(1.0, help="Replay speed of the sensor scenario (2 = twice as fast)."),
    scenario: Optional[Path] = typer.Option(None, help="Entrance scenario (default: scenarios/teahouse-reception.yaml)."),
    tables: Optional[Path] = typer.Option(None, help="Tables scenario (default: scenarios/teahouse-tables.yaml)."),
    config: Optional[Path] = ConfigOption,
) -> None:
    """The teahouse reception end to end: the gateway (as `printeps serve` builds it, with its ROS
    node) and the sensor and Pepper simulators; prints what happens and a summary. Without
    --headless the gateway keeps running (workbench at http://127.0.0.1:8080/workbench) until Ctrl-C."""
    from gateway.base.logs import log_off_thread
    from gateway.demo import run_demo

    # as printeps serve: no serving thread waits on a stderr nobody reads (the demo shows warnings
    # and errors only, as before: its own narration is the story)
    log_off_thread(logging.WARNING)
    sys.setswitchinterval(0.001)  # short GIL hand-offs between the ROS executor and the workers
    summary: dict[str, Any] = {}
    _run_or_explain(lambda: summary.update(run_demo(_settings(config), headless=headless, scenario=scenario,
                                                    tables=tables, speed=speed)))
    if summary.get("failed"):
        raise typer.Exit(1)


@app.command("export")
def export_cmd(
    folder: Path = typer.Argument(..., help="Folder to write (the repository's seed layout)."),
    config: Optional[Path] = ConfigOption,
) -> None:
    """Write the current version of every rule set, workflow, knowledge file, query and mapping
    from the Information State into FOLDER (for git). Joins a running embedded database."""
    from gateway.store import open_store
    from gateway.store.catalog import MongoCatalog
    from gateway.runtime.transfer import export_to, seed_folders

    settings = _settings(config)
    store = _open_store_or_fail(open_store, settings)
    try:
        written = export_to(MongoCatalog(store.db, "export"), folder, seed_folders(settings))
    finally:
        store.close()
    for rel in written:
        typer.echo(f"{folder / rel}")
    typer.echo(f"exported {len(written)} files to {folder}")


@app.command("import")
def import_cmd(
    folder: Path = typer.Argument(..., help="A folder in the seed layout (e.g. written by `printeps export`)."),
    comment: str = typer.Option("", help="Version comment for what changes."),
    author: str = typer.Option(os.environ.get("USER", "import"), help="Author recorded with the new versions."),
    role: Optional[str] = typer.Option(None, "--role", callback=lambda v: v if v is None else _role(v),
                                       help="Import as this role: 'author' applies the rule policy to each rule set "
                                            "(default: the machine's own rights, logged as 'local')."),
    config: Optional[Path] = ConfigOption,
) -> None:
    """Make each item of FOLDER that differs from the current version a new version, checked like a
    deploy; running gateways follow within a second. Exit 1 if any item was refused."""
    from gateway.app import build_gateway
    from gateway.store import open_store
    from gateway.runtime.transfer import import_from

    if not folder.is_dir():
        _fail(f"{folder}: no such folder", code=2)
    settings = _settings(config)
    store = _open_store_or_fail(open_store, settings)
    try:
        gateway = build_gateway(settings, rest=False, ros=False, store=store, seed=False, warm_up=False, follow=False)
        try:
            report = import_from(gateway, folder, author=author, comment=comment or f"imported from {folder}",
                                 role=role)
        finally:
            gateway.close()
    finally:
        store.close()
    for item, outcome in report:
        typer.echo(f"{item}: {outcome}")
    if any(outcome.startswith("failed") for _, outcome in report):
        raise typer.Exit(1)


def _open_store_or_fail(open_store: Any, settings: Any) -> Any:
    from gateway.store.embedded import EmbeddedDbError

    try:
        store = open_store(settings, join_running=True)
        store.ping()
        return store
    except (EmbeddedDbError, Exception) as exc:  # noqa: B014 - any start failure is reported, not traced
        _fail(f"printeps: cannot reach the Information State: {exc}", code=3)
    raise AssertionError  # unreachable


@rules_app.command("validate")
def rules_validate(
    path: Path = typer.Argument(..., help="A rule set folder or a single .drl/.dslr file."),
    role: str = RoleOption,
    config: Optional[Path] = ConfigOption,
) -> None:
    """Compile locally; print ``file:line:col: message`` per problem and exit 1 if there is any.
    With ``--role author``, first what the rule policy refuses (as a gateway would for an author)."""
    from gateway.engine import Engine, EngineError

    name, files = read_ruleset(path)
    folder = path if path.is_dir() else path.parent
    engine = Engine(_settings(config))
    from gateway.runtime.progress import TerminalProgress

    progress = TerminalProgress() if sys.stderr.isatty() else None  # big sets take a while: show how far
    try:
        errors = [e.to_dict() for e in engine.validate(name, files, on_progress=progress, role=role)]
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


# --- issue 16: rule test scenarios ------------------------------------------------------------


@rules_app.command("test")
def rules_test(
    path: Optional[Path] = typer.Argument(None, help="A rule set folder with tests/*.yaml (run locally; "
                                                      "with --server its files are tested there as a draft)."),
    server: Optional[str] = typer.Option(None, help="Run on this gateway; without PATH, test the deployed --ruleset."),
    ruleset: Optional[str] = typer.Option(None, help="Rule set name (default: the folder name)."),
    version: Optional[int] = typer.Option(None, help="With --server and no PATH: this stored version (default: current)."),
    token: Optional[str] = typer.Option(None, help="Token (default: $PRINTEPS_TOKEN)."),
    junit: Optional[Path] = typer.Option(None, "--junit", help="Also write the results as JUnit XML to this file."),
    role: str = RoleOption,
    config: Optional[Path] = ConfigOption,
) -> None:
    """Run a rule set's test scenarios; print green/red per scenario and the rules no scenario
    fires; exit 1 if any scenario is red or the rules do not compile."""
    from gateway.engine.scenarios import junit_xml, text_report

    folder = None
    if path is not None:
        if not path.is_dir():
            _fail(f"{path}: not a rule set folder", code=2)
        folder_name, files = read_ruleset(path)
        name, folder = ruleset or folder_name, path
    elif server:
        if not ruleset:
            _fail("--ruleset NAME is needed with --server and no folder", code=2)
        name, files = ruleset, None
    else:
        _fail("give a rule set folder, or --server URL --ruleset NAME", code=2)
        raise AssertionError  # unreachable
    if server:
        report = _test_on_server(_server(server), name, files, version, token, folder)
    else:
        from gateway.engine import Engine, EngineError
        from gateway.engine.scenarios import run_scenarios

        engine = Engine(_settings(config))
        try:
            report = run_scenarios(engine, files, name, role=role).to_dict()
        except EngineError as exc:
            body = exc.to_dict()
            for line in format_errors(body.get("errors") or [{"message": str(exc)}], folder):
                typer.echo(line)
            raise typer.Exit(1)
    for line in text_report(report, str(folder) if folder else None):
        typer.echo(line)
    if junit is not None:
        junit.write_text(junit_xml(report), encoding="utf-8")
    if not report.get("ok"):
        raise typer.Exit(1)


def _test_on_server(url: str, name: str, files: Optional[dict[str, str]], version: Optional[int],
                    token: Optional[str], folder: Optional[Path]) -> dict[str, Any]:
    import httpx

    body: dict[str, Any] = {"files": files} if files is not None else ({"version": version} if version else {})
    endpoint = f"{url}/api/rulesets/{name}/test"
    try:
        response = httpx.post(endpoint, json=body, headers=_headers(token), timeout=300)
    except httpx.HTTPError as exc:
        _fail(f"{endpoint}: {exc}")
    data = _json_or_text(response)
    if response.status_code == 200 and isinstance(data, dict):
        return data
    if response.status_code == 422 and isinstance(data, dict) and data.get("errors"):
        for line in format_errors(data["errors"], folder):
            typer.echo(line)
        raise typer.Exit(1)
    _fail(f"{endpoint}: HTTP {response.status_code}: {data.get('error') if isinstance(data, dict) else data}")
    raise AssertionError  # unreachable


# --- end issue 16 --------------------------------------------------------------------------------


@rules_app.command("deploy")
def rules_deploy(
    path: Path = typer.Argument(..., help="A rule set folder (its name is the rule set name)."),
    server: Optional[str] = typer.Option(None, help=f"Gateway URL (default: $PRINTEPS_SERVER or {DEFAULT_SERVER})."),
    token: Optional[str] = typer.Option(None, help="Author token (default: $PRINTEPS_TOKEN)."),
    name: Optional[str] = typer.Option(None, help="Rule set name (default: the folder name)."),
    comment: str = typer.Option("", help="Version comment."),
    base_version: Optional[int] = typer.Option(None, help="Refuse (409) if the current version is not this."),
    force: bool = typer.Option(False, "--force", help="Deploy even if test scenarios are red."),
) -> None:
    """Deploy a rule set folder to a running gateway (PUT /api/rulesets/{name}); a red test
    scenario refuses the deploy unless --force."""
    import httpx

    folder_name, files = read_ruleset(path)
    name = name or folder_name
    folder = path if path.is_dir() else path.parent
    body: dict[str, Any] = {"files": files, "comment": comment}
    if force:
        body["force"] = True
    if base_version is not None:
        body["base_version"] = base_version
    url = f"{_server(server)}/api/rulesets/{name}"
    try:  # as a build job: a big rule set takes longer than one HTTP request should wait
        response = httpx.put(url, json=body, headers={**_headers(token), "Prefer": "respond-async"}, timeout=120)
        status, data = response.status_code, _json_or_text(response)
        if status == 202:
            status, data = _follow_job(_server(server), response.headers["location"], token)
    except httpx.HTTPError as exc:
        _fail(f"{url}: {exc}")
    if status == 201:
        typer.echo(f"deployed {data['name']} version {data['version']}")
        return
    if status == 422 and isinstance(data, dict) and data.get("errors"):
        for line in format_errors(data["errors"], folder):
            typer.echo(line)
        if data.get("kind") == "scenarios":  # issue 16: red test scenarios refuse the deploy
            typer.echo(str(data.get("error")).replace('deploy with "force": true', "deploy with --force"))
        raise typer.Exit(1)
    if status == 409 and isinstance(data, dict) and data.get("current") is not None:
        _fail(f"{url}: HTTP 409: {data.get('error')}: the current version is {data['current']}"
              f"{'' if base_version is None else f', not {base_version}'} (deploy again with --base-version {data['current']})")
    _fail(f"{url}: HTTP {status}: {data.get('error') if isinstance(data, dict) else data}")


def _follow_job(server: str, location: str, token: Optional[str], succeeded: Any = None) -> tuple[int, Any]:
    """Poll a build job to its end, drawing its progress on a terminal; answers (status, body) as
    the synchronous call would have (``succeeded(result)`` makes it from a finished job's result;
    default: a deploy's)."""
    import time

    import httpx

    from gateway.runtime.progress import TerminalProgress

    progress = TerminalProgress() if sys.stderr.isatty() else None
    try:
        while True:
            job = httpx.get(f"{server}{location}", headers=_headers(token), timeout=30).json()
            step = job.get("progress")
            if progress is not None and step:
                progress(step["done"], step["total"], step["stage"])
            if job["status"] == "succeeded":
                if succeeded is not None:
                    return succeeded(job["result"])
                version = job["result"]["version"]
                return 201, {"name": version["name"], "version": version["version"]}
            if job["status"] in ("failed", "cancelled"):
                error = job.get("error") or {}
                return int(error.get("status", 500)), error
            time.sleep(0.2)
    except KeyboardInterrupt:  # Ctrl-C: stop the build on the server too, as the user means
        answer = httpx.delete(f"{server}{location}", headers=_headers(token), timeout=30)
        said = "cancelling the build" if answer.status_code in (200, 202) else _json_or_text(answer)
        _fail(f"interrupted: {said} ({location})")
    finally:
        if progress is not None:
            progress.close()


@rules_app.command("replay")
def rules_replay(
    path: Path = typer.Argument(..., help="The candidate: a rule set folder (its name is the rule set name)."),
    server: Optional[str] = typer.Option(None, help=f"Gateway URL (default: $PRINTEPS_SERVER or {DEFAULT_SERVER})."),
    token: Optional[str] = typer.Option(None, help="Token (default: $PRINTEPS_TOKEN)."),
    name: Optional[str] = typer.Option(None, help="Rule set name (default: the folder name)."),
    since: Optional[str] = typer.Option(None, help="Replay decisions from this ISO-8601 time on."),
    until: Optional[str] = typer.Option(None, help="... and before this one."),
    origin: Optional[str] = typer.Option(None, help="Only decisions of this origin (rest, kie, stream, ros, workflow)."),
    limit: int = typer.Option(1000, help="The newest N decisions of the selection (at most 100,000)."),
    max_changes: int = typer.Option(20, help="Changed decisions listed (all are counted)."),
    fail_on_change: bool = typer.Option(False, "--fail-on-change", help="Exit 1 when any decision changed."),
    junit: Optional[Path] = typer.Option(None, "--junit", help="Also write the result as JUnit XML to this file."),
) -> None:
    """Replay the recorded decisions of a rule set on the folder's files (a draft, never deployed)
    and print how many changed and how often each rule fires before and after. Exit 1 when the
    folder does not compile or the server refuses; with --fail-on-change, also when anything changed."""
    import httpx

    from gateway.engine.replay import junit_xml, text_table

    folder_name, files = read_ruleset(path)
    name = name or folder_name
    folder = path if path.is_dir() else path.parent
    body: dict[str, Any] = {"files": files, "limit": limit, "max_changes": max_changes}
    body.update({k: v for k, v in (("since", since), ("until", until), ("origin", origin)) if v is not None})
    url = f"{_server(server)}/api/rulesets/{name}/replay"
    try:  # as a job: 100,000 decisions take longer than one HTTP request should wait
        response = httpx.post(url, json=body, headers={**_headers(token), "Prefer": "respond-async"}, timeout=120)
        status, data = response.status_code, _json_or_text(response)
        if status == 202:
            status, data = _follow_job(_server(server), response.headers["location"], token,
                                       succeeded=lambda result: (200, result))
    except httpx.HTTPError as exc:
        _fail(f"{url}: {exc}")
    if status == 422 and isinstance(data, dict) and data.get("errors") and data["errors"][0].get("file"):
        for line in format_errors(data["errors"], folder):
            typer.echo(line)
        raise typer.Exit(1)
    if status != 200 or not isinstance(data, dict):
        _fail(f"{url}: HTTP {status}: {data.get('error') if isinstance(data, dict) else data}")
    for line in text_table(data):
        typer.echo(line)
    if junit is not None:
        junit.write_text(junit_xml(data, fail_on_change), encoding="utf-8")
    if fail_on_change and (data.get("changed") or data.get("failed")):
        raise typer.Exit(1)


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

    engine = Engine(_settings(config))  # local: the rule sets of the rules dir, in memory
    try:
        engine.seed(engine.settings.engine.rules_dir)
        result = engine.fire(ruleset, facts, origin="cli")
    except EngineError as exc:
        _print_json(exc.to_dict())
        raise typer.Exit(1)
    _print_json(result.to_dict())


@workflow_app.command("validate")
def workflow_validate(files: list[Path] = typer.Argument(..., help="Workflow YAML files.")) -> None:
    """Check workflow files against the schema and their references: ``file:line:column: path:
    message`` per problem, exit 1 on any."""
    from gateway.workflow.loader import WorkflowInvalid, load

    failed = False
    for path in files:
        try:
            wf = load(path)
        except WorkflowInvalid as exc:
            failed = True
            for problem in exc.problems:
                typer.echo(str(problem), err=True)
        except OSError as exc:
            failed = True
            typer.echo(f"{path}: {exc.strerror}", err=True)
        else:
            typer.echo(f"{path}: ok ({wf.name})")
    if failed:
        raise typer.Exit(1)


@workflow_app.command("generate")
def workflow_generate(
    file: Path = typer.Argument(..., help="A workflow YAML file."),
    output: Optional[Path] = typer.Option(None, "--output", "-o", help="Default: standard output."),
) -> None:
    """Write the workflow as a standalone rclpy node (what the papers' editor generated)."""
    from gateway.workflow.codegen import generate
    from gateway.workflow.loader import WorkflowInvalid, load

    try:
        source = generate(load(file))
    except WorkflowInvalid as exc:
        _fail(str(exc))
    if output:
        output.write_text(source, encoding="utf-8")
    else:
        typer.echo(source, nl=False)


@app.command("build-java")
def build_java(config: Optional[Path] = ConfigOption) -> None:
    """Compile the Java helpers (java/src) into the cache, then train the JVM's AOT class cache
    (Java 25+: a process that compiles rules then spends ~2 CPU-s less on it; see docs/operations.md)."""
    from gateway.base import jvm
    from gateway.engine import jvm_training

    settings = _settings(config)
    try:
        jvm.start(settings.jvm)
    except jvm.JvmError as exc:
        _fail(str(exc))
    try:
        cache = jvm_training.build(settings)
    except jvm_training.TrainingError as exc:
        # the cache only makes starts cheaper: without it everything runs as before
        typer.echo(f"JVM started; Java helpers compiled; no AOT class cache: {exc}", err=True)
        return
    typer.echo("JVM started; Java helpers compiled; "
               + (f"AOT class cache {cache}" if cache else "no AOT class cache (needs Java 25+, jvm.aot_cache)"))


def _json_or_text(response: Any) -> Any:
    try:
        return response.json()
    except ValueError:
        return response.text


def main() -> None:  # pragma: no cover - console entry point alternative
    app(prog_name="printeps")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
