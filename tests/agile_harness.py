"""The agile loop of the teahouse paper (Table 2, suggestions 1-16), replayed on a running gateway.

Why this module: PRINTEPS promises that a domain expert's feedback goes live in minutes by editing a
workflow, a business rule, the ontology or a SWRL rule. Each scenario here is one suggestion: the
concrete edit, a probe that observes the robots' behaviour, and the behaviour expected after the
edit. :func:`apply` checks the old behaviour, submits the edit to the running gateway, and measures
the edit's size and the machine time from submit until the probe shows the new behaviour.
The tests (``tests/agile``, the workbench's Table 2 story) and the benchmarks (``bench/agile_loop.py``,
``bench/table2_browser.py``) share these definitions. It is test support, not product: it lives in
``tests/`` (imported as ``agile_harness``) and may import the gateway's top, the composition root and
its entry points.

Scenarios build on each other in Table 2 order (the teahouse evolves: #11 extends the rule set
that #8 created), so run them in order on one gateway.

Everything is edited through the REST API (PUT), as the workbench does: workflows, rule sets, the
ontology and the SWRL rules.
"""

from __future__ import annotations

import difflib
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import httpx

from gateway.app import build_gateway
from gateway.config import PROJECT_ROOT, Settings
from gateway.serve import free_port, serve_in_thread

Observation = list[str]


class ChangeRequestFailed(AssertionError):
    """A scenario's before/after behaviour was not what the suggestion asks for."""


# ---------------------------------------------------------------- talking to the gateway


class OwnerClient:
    """The running gateway as an owner's tools see it: its REST API (and its knowledge files)."""

    def __init__(self, base_url: str, *, token: str | None = None, timeout: float = 30.0) -> None:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self.http = httpx.Client(base_url=base_url, headers=headers, timeout=timeout)
        self.failed_requests: list[str] = []

    def close(self) -> None:
        self.http.close()

    def _call(self, method: str, path: str, ok: tuple[int, ...] = (200, 201), **kwargs: Any) -> httpx.Response:
        response = self.http.request(method, path, **kwargs)
        if response.status_code not in ok:
            self.failed_requests.append(f"{method} {path} -> {response.status_code}: {response.text[:300]}")
            raise ChangeRequestFailed(self.failed_requests[-1])
        return response

    # workflows
    def run(self, workflow: str, inputs: dict[str, Any] | None = None) -> dict[str, Any]:
        result = self._call("POST", f"/api/workflows/{workflow}/run", json={"inputs": inputs or {}}).json()
        if result["status"] != "succeeded":
            raise ChangeRequestFailed(f"run of {workflow} failed: {result['error']}")
        return result

    def workflow_text(self, name: str) -> tuple[str, int]:
        body = self._call("GET", f"/api/workflows/{name}").json()
        return body["text"], body["version"]

    def put_workflow(self, name: str, text: str, base_version: int, comment: str) -> None:
        self._call("PUT", f"/api/workflows/{name}", json={"text": text, "base_version": base_version,
                                                           "comment": comment})

    # rule sets
    def ruleset_files(self, name: str) -> tuple[dict[str, str], int | None]:
        response = self._call("GET", f"/api/rulesets/{name}", ok=(200, 404))
        if response.status_code == 404:
            return {}, None
        body = response.json()
        return dict(body["files"]), body.get("version") or body.get("info", {}).get("version")

    def put_ruleset(self, name: str, files: dict[str, str], base_version: int | None, comment: str) -> None:
        body: dict[str, Any] = {"files": files, "comment": comment}
        if base_version is not None:
            body["base_version"] = base_version
        self._call("PUT", f"/api/rulesets/{name}", json=body)

    # knowledge
    def reason(self, individuals: list[dict[str, Any]]) -> dict[str, Any]:
        return self._call("POST", "/api/reason", json={"individuals": individuals}).json()

    def knowledge_text(self, kind: str) -> str:
        return self._call("GET", f"/api/knowledge/{kind}").json()["text"]

    def put_knowledge(self, kind: str, text: str) -> None:
        """Replace the ontology or the SWRL rules through the REST API (checked, then live)."""
        self._call("PUT", f"/api/knowledge/{kind}", json={"text": text, "comment": "Table 2 change request"})



# ---------------------------------------------------------------- what the robots did


def _summary(params: dict[str, Any]) -> str:
    for key in ("text", "name", "location", "prompt", "data"):
        if params.get(key):
            return str(params[key])
    if "x" in params:
        return f"({float(params['x']):.2f}, {float(params['y']):.2f})"
    if "seconds" in params:
        return f"{params['seconds']}s"
    return ""


def behaviour(run: dict[str, Any]) -> Observation:
    """A run as what people saw: ``"pepper say: Please follow me."``, in order."""
    out = []
    for step in run["steps"]:
        if step["type"] == "module" and step["kind"] in ("ros_service", "ros_topic", "manual", "wait") \
                and step["status"] == "ok":
            out.append(f"{step['actor'] or ''} {step['module']}: {_summary(step['params'])}".strip())
    return out


def inferred(result: dict[str, Any], subject: str) -> Observation:
    """Inferred ``property = value`` facts about one individual (from POST /api/reason)."""
    out = []
    for fact in result["inferred"]:
        if str(fact["subject"]).rsplit("/", 1)[-1] == subject:
            out.append(f"{str(fact['predicate']).rsplit('/', 1)[-1]} = {fact['object']}")
    return sorted(out)


# ---------------------------------------------------------------- scenarios


@dataclass
class Edit:
    """One change: ``kind`` workflow | ruleset | ontology | swrl; ``change`` maps old content to new
    (text for workflow/ontology/swrl, a files dict for a rule set)."""

    kind: str
    target: str
    change: Callable[[Any], Any]


@dataclass
class Scenario:
    id: int
    suggestion: str
    category: str
    paper_time: str
    edits: list[Edit]
    probe: Callable[[OwnerClient], Observation]
    expect: Callable[[Observation], bool]
    what: str = ""


@dataclass
class Measurement:
    id: int
    category: str
    suggestion: str
    paper_time: str
    edit: str
    lines_changed: int
    chars_changed: int
    submit_ms: float
    submit_to_live_ms: float
    before: Observation
    after: Observation
    failed_requests: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.failed_requests


def _replace(old: str, new: str, count: int = 1) -> Callable[[str], str]:
    """A text edit that must find ``old`` exactly ``count`` times (count=0: at least once, all)."""

    def change(text: str) -> str:
        found = text.count(old)
        if (count and found != count) or found == 0:
            raise ChangeRequestFailed(f"edit anchor {old!r} found {found} times, expected {count or 'some'}")
        return text.replace(old, new)

    return change


def _add_file(name: str, content: str) -> Callable[[dict[str, str]], dict[str, str]]:
    def change(files: dict[str, str]) -> dict[str, str]:
        return {**files, name: content}

    return change


def _append_to_file(name: str, content: str) -> Callable[[dict[str, str]], dict[str, str]]:
    def change(files: dict[str, str]) -> dict[str, str]:
        if name not in files:
            raise ChangeRequestFailed(f"rule set has no file {name!r} (files: {', '.join(files)})")
        return {**files, name: files[name].rstrip("\n") + "\n" + content}

    return change


def _run(workflow: str, inputs: dict[str, Any] | None = None) -> Callable[[OwnerClient], Observation]:
    return lambda gw: behaviour(gw.run(workflow, inputs))


def _before(obs: Observation, first: str, then: str) -> bool:
    """``first`` happens, and before the first ``then``."""
    firsts = [i for i, o in enumerate(obs) if first in o]
    thens = [i for i, o in enumerate(obs) if then in o]
    return bool(firsts and thens and firsts[0] < thens[0])


TABLES = [{"type": "Table", "id": "table1", "seats": 2, "free": True, "dirty": False},
          {"type": "Table", "id": "table2", "seats": 4, "free": True, "dirty": True},
          {"type": "Table", "id": "table3", "seats": 4, "free": False, "dirty": False}]

SEAT_INFO_DRL = '''\
package org.printeps.seatinfo;

import org.printeps.gateway.Actions;

global Actions actions;

// A table of the teahouse as the seat sensing sees it.
declare Table
    id : String
    seats : int
    free : boolean
    dirty : boolean
end

rule "Tell the party how many tables are free"
when
    accumulate(Table(free == true); $n : count(1))
then
    actions.say("pepper", "We have " + $n + " free tables for you today.");
end
'''

DIRTY_TABLE_DRL = '''
rule "Tell the party that a dirty table is being cleaned"
when
    Table(free == true, dirty == true, $id : id)
then
    actions.say("pepper", "Table " + $id + " is being cleaned for you. Please wait a moment.");
end
'''

BLANKET_DSLR = '''
rule "Offer blankets"
    salience 5
when
    There is a party at the entrance
    Everyone in the party has a type
then
    Pepper says "Would you like a blanket for your legs?"
end
'''

SAY_MODULE = "  say: {kind: ros_service, actor: pepper, service: /pepper/speak, type: printeps_interfaces/srv/Speak, params: {robot: pepper}}\n"


def scenarios() -> list[Scenario]:
    """Table 2, suggestions 1-16, in the paper's order."""
    greeting_inputs = {"tables": TABLES}
    return [
        Scenario(1, "Communicate out loud before moving", "WF", "2:48",
                 [Edit("workflow", "show_to_seat", _replace(
                     "      - id: go_to_table\n",
                     "      - id: announce_move\n        module: say\n"
                     "        with: {text: \"I will show you to your table. Please follow me.\"}\n"
                     "      - id: go_to_table\n"))],
                 _run("show_to_seat"), lambda o: _before(o, "say: I will show you", "move_to: (3.50"),
                 "Pepper speaks before leading the party to the table"),
        Scenario(2, "Make informative bodily gestures before moving", "WF", "4:57",
                 [Edit("workflow", "show_to_seat", _replace(
                     "      - id: go_to_table\n",
                     "      - id: point_the_way\n        module: gesture\n"
                     "        with: {name: point to the table}\n"
                     "      - id: go_to_table\n"))],
                 _run("show_to_seat"), lambda o: _before(o, "gesture: point to the table", "move_to: (3.50"),
                 "Pepper points the way before moving"),
        Scenario(3, "Chef robots should execute some type of performance while idle", "WF", "8:22",
                 [Edit("workflow", "prepare_drinks", _replace(
                     "            with: {name: place cups on the pass}\n",
                     "            with: {name: place cups on the pass}\n"
                     "        else:\n"
                     "          - id: idle_performance\n            module: jaco2_motion\n"
                     "            with: {name: tea ceremony performance}\n"))],
                 _run("prepare_drinks", {"orders": []}), lambda o: any("tea ceremony performance" in x for x in o),
                 "with no order, Jaco2 performs"),
        Scenario(4, "When arriving at the table, invite customers to sit down", "WF", "1:40",
                 [Edit("workflow", "show_to_seat", _replace(
                     "        with: {x: \"${input.table.x - table_distance.value}\", y: \"${input.table.y}\"}\n",
                     "        with: {x: \"${input.table.x - table_distance.value}\", y: \"${input.table.y}\"}\n"
                     "      - id: invite_to_sit\n        module: say\n"
                     "        with: {text: \"Here is your table. Please have a seat.\"}\n"))],
                 _run("show_to_seat"), lambda o: _before(o, "move_to: (3.50", "Please have a seat."),
                 "Pepper invites the party to sit once at the table"),
        Scenario(5, "Teach robots proper timing for responding to customers", "WF", "2:23",
                 [Edit("workflow", "take_order", _replace(
                     "  publish_order:", "  pause: {kind: wait, params: {seconds: 0.2}}\n  publish_order:")),
                  Edit("workflow", "take_order", _replace(
                     "      - id: confirm_order\n",
                     "      - id: let_them_finish\n        module: pause\n"
                     "      - id: confirm_order\n"))],
                 _run("take_order"), lambda o: _before(o, "pause: 0.2s", "certainly."),
                 "Pepper waits 0.2 s after the order before answering"),
        Scenario(6, "Communicate out loud when visiting the table before ordering", "WF", "1:09",
                 [Edit("workflow", "take_order", _replace(
                     "      - id: go_to_table\n",
                     "      - id: announce_visit\n        module: say\n"
                     "        with: {text: \"Excuse me, I am coming to take your order.\"}\n"
                     "      - id: go_to_table\n"))],
                 _run("take_order"), lambda o: _before(o, "I am coming to take your order", "move_to"),
                 "Pepper announces its visit before going to the table"),
        Scenario(7, "Communicate out loud when visiting the table before paying the bill", "WF", "3:40",
                 [Edit("workflow", "settle_bill", _replace(
                     "      - id: settle_bill\n",
                     "      - id: go_to_table\n        module: move_to\n"
                     "        with: {x: \"${input.table.x - 0.5}\", y: \"${input.table.y}\"}\n"
                     "      - id: announce_bill\n        module: say\n"
                     "        with: {text: \"Thank you. Our staff will bring your bill now.\"}\n"
                     "      - id: settle_bill\n"))],
                 _run("settle_bill"), lambda o: _before(o, "Our staff will bring your bill", "staff_task"),
                 "Pepper visits and speaks before the staff settles the bill"),
        Scenario(8, "Identify available seats and the information table and deliver an informative "
                    "statement together with the welcoming greeting", "WF+BR", "16:22+5:38",
                 [Edit("ruleset", "seat_info", _add_file("seat_info.drl", SEAT_INFO_DRL)),
                  Edit("workflow", "greeting", _replace(
                      "processes:\n",
                      "  fire_seat_info_rules:\n    kind: fire_rules\n    actor: gateway\n    ruleset: seat_info\n"
                      "    dispatch: {say: say}\nprocesses:\n")),
                  Edit("workflow", "greeting", _replace(
                      "        save: reception\n",
                      "        save: reception\n"
                      "      - id: seat_info_rules\n        module: fire_seat_info_rules\n"
                      "        with: {facts: \"${input.tables}\"}\n"))],
                 _run("greeting", greeting_inputs), lambda o: _before(o, "Welcome", "2 free tables for you today"),
                 "after the welcome, Pepper tells how many tables are free"),
        Scenario(9, "Enlarge bodily gestures accompanying welcoming greetings", "BR", "2:11",
                 [Edit("ruleset", "reception", lambda files: {
                     **files, "reception.dslr": _replace('Pepper gestures "bow"\n',
                                                         'Pepper gestures "deep bow with open arms"\n', 0)(
                         files["reception.dslr"])})],
                 _run("greeting", greeting_inputs),
                 lambda o: any("gesture: deep bow with open arms" in x for x in o) and not any(
                     x.endswith("gesture: bow") for x in o),
                 "Pepper's greeting bow becomes a deep bow with open arms"),
        Scenario(10, "Ask all customers whether they would like a blanket for their legs", "BR", "3:19",
                 [Edit("ruleset", "reception", _append_to_file("reception.dslr", BLANKET_DSLR))],
                 _run("greeting", greeting_inputs), lambda o: _before(o, "Welcome", "blanket for your legs"),
                 "after the welcome, Pepper offers the party blankets"),
        Scenario(11, "When the table is dirty, inform the customer that the robot is cleaning it", "BR", "2:08",
                 [Edit("ruleset", "seat_info", _append_to_file("seat_info.drl", DIRTY_TABLE_DRL))],
                 _run("greeting", greeting_inputs), lambda o: any("table2 is being cleaned" in x for x in o),
                 "Pepper says that the dirty free table is being cleaned"),
        Scenario(12, "Change the distance between robot and human", "Onto", "0:31",
                 [Edit("ontology", "teahouse.ttl", _replace(
                     'printeps:robotToHumanDistance "1.0"^^xsd:decimal',
                     'printeps:robotToHumanDistance "1.5"^^xsd:decimal'))],
                 _run("show_to_seat"), lambda o: any("move_to: (2.50, 0.00)" in x for x in o),
                 "Pepper stops 1.5 m from the party instead of 1.0 m"),
        Scenario(13, "Change the distance between robot and table", "Onto", "1:00",
                 [Edit("ontology", "teahouse.ttl", _replace(
                     'printeps:robotToTableDistance "0.5"^^xsd:decimal',
                     'printeps:robotToTableDistance "0.8"^^xsd:decimal'))],
                 _run("show_to_seat"), lambda o: any("move_to: (3.20, 2.00)" in x for x in o),
                 "Pepper stops 0.8 m before the table instead of 0.5 m"),
        Scenario(14, "Accelerate the speed of reaction to empty cups", "Onto", "6:05",
                 [Edit("ontology", "teahouse.ttl", _replace(
                     'printeps:emptyCupReactionTime "30"^^xsd:decimal',
                     'printeps:emptyCupReactionTime "15"^^xsd:decimal'))],
                 _run("serving", {"cups": [{"table": "table1", "empty_for_s": 20}]}),
                 lambda o: any("Refill the empty cups" in x for x in o),
                 "a cup empty for 20 s is refilled (reaction time 30 s -> 15 s)"),
        Scenario(15, "Reduce the age threshold for providing child seats", "SWRL", "1:20",
                 [Edit("swrl", "teahouse.swrl", _replace("lessThan(?a, 7) -> needsChildSeat(?c, true)",
                                                         "lessThan(?a, 6) -> needsChildSeat(?c, true)"))],
                 lambda gw: inferred(gw.reason([{"id": "kid6", "types": ["Customer"], "properties": {"age": 6}}]),
                                     "kid6"),
                 lambda o: not any(x.startswith("needsChildSeat") for x in o),
                 "a 6-year-old no longer gets a child seat (threshold 7 -> 6)"),
        Scenario(16, "Slightly decrease the quantity of beverage poured", "SWRL", "3:43",
                 [Edit("swrl", "teahouse.swrl", _replace("multiply(?quantity, ?capacity, 0.8)",
                                                         "multiply(?quantity, ?capacity, 0.7)"))],
                 lambda gw: inferred(gw.reason([{"id": "cup200", "types": ["Cup"],
                                                 "properties": {"cupCapacity": 200}}]), "cup200"),
                 lambda o: "pourQuantity = 140.0" in o,
                 "a 200 ml cup gets 140 ml instead of 160 ml"),
    ]


# ---------------------------------------------------------------- applying and measuring


def _diff_size(old: str, new: str) -> tuple[int, int]:
    lines = sum(1 for line in difflib.unified_diff(old.splitlines(), new.splitlines(), lineterm="", n=0)
                if line[:1] in "+-" and not line.startswith(("+++", "---")))
    matcher = difflib.SequenceMatcher(None, old, new, autojunk=False)
    chars = sum(max(i2 - i1, j2 - j1) for tag, i1, i2, j1, j2 in matcher.get_opcodes() if tag != "equal")
    return lines, chars


def _prepare(gw: OwnerClient, edit: Edit) -> tuple[Callable[[], None], int, int]:
    """Fetch the current content, compute the new one; returns (submit, lines, chars)."""
    comment = f"Table 2: {edit.kind} edit"
    if edit.kind == "workflow":
        text, version = gw.workflow_text(edit.target)
        new = edit.change(text)
        return (lambda: gw.put_workflow(edit.target, new, version, comment)), *_diff_size(text, new)
    if edit.kind == "ruleset":
        files, version = gw.ruleset_files(edit.target)
        new_files = edit.change(dict(files))
        lines = chars = 0
        for name in sorted(set(files) | set(new_files)):
            more_lines, more_chars = _diff_size(files.get(name, ""), new_files.get(name, ""))
            lines, chars = lines + more_lines, chars + more_chars
        return (lambda: gw.put_ruleset(edit.target, new_files, version, comment)), lines, chars
    text = gw.knowledge_text(edit.kind)
    new = edit.change(text)
    return (lambda: gw.put_knowledge(edit.kind, new)), *_diff_size(text, new)


def apply(gw: OwnerClient, scenario: Scenario, *, live_timeout: float = 10.0) -> Measurement:
    """Check the old behaviour, submit the edits, wait (bounded) until the new behaviour shows."""
    gw.failed_requests.clear()
    before = scenario.probe(gw)
    if scenario.expect(before):
        raise ChangeRequestFailed(f"#{scenario.id}: the new behaviour is already there before the edit: {before}")
    lines = chars = 0
    submit_s = 0.0
    for edit in scenario.edits:
        # prepared one after the other: edits of one target build on the version the previous made
        submit, more_lines, more_chars = _prepare(gw, edit)  # authoring: not part of submit-to-live
        lines, chars = lines + more_lines, chars + more_chars
        t_submit = time.perf_counter()
        submit()
        submit_s += time.perf_counter() - t_submit
    t_last = time.perf_counter()
    deadline = time.monotonic() + live_timeout
    after = scenario.probe(gw)
    while not scenario.expect(after):
        if time.monotonic() > deadline:
            raise ChangeRequestFailed(f"#{scenario.id}: not live within {live_timeout}s; behaviour now: {after}")
        time.sleep(0.01)
        after = scenario.probe(gw)
    live_s = submit_s + (time.perf_counter() - t_last)
    return Measurement(scenario.id, scenario.category, scenario.suggestion, scenario.paper_time,
                       " + ".join(f"{e.kind} {e.target}" for e in scenario.edits), lines, chars,
                       round(submit_s * 1e3, 1), round(live_s * 1e3, 1), before, after,
                       list(gw.failed_requests))


# ---------------------------------------------------------------- a gateway to replay on


@contextmanager
def running_gateway(workdir: str | Path, *, token: str | None = None) -> Iterator[OwnerClient]:
    """A real gateway, built as ``printeps serve`` builds it (no ROS: robots and humans are
    simulated), over its own embedded Information State in ``workdir`` seeded from the
    repository, served by uvicorn on 127.0.0.1."""
    workdir = Path(workdir)
    settings = Settings.model_validate({
        "data_dir": str(workdir / "var"),
        "engine": {"rules_dir": str(PROJECT_ROOT / "rules" / "drl")},
        "workflows": {"simulate_robots": True, "simulate_humans": True},
    })
    gateway = build_gateway(settings, rest=True, ros=False, warm_up=False)
    try:
        gateway.engine.warm_up(background=False)  # as a gateway that has been up a while: `serve` warms up at start
        server, thread = serve_in_thread(gateway.app, free_port(), name="agile-gateway")
        gw = OwnerClient(f"http://127.0.0.1:{server.config.port}", token=token)
        try:
            yield gw
        finally:
            gw.close()
            server.should_exit = True
            thread.join(timeout=10)
    finally:
        gateway.close()
