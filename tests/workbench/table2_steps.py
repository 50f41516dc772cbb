"""Table 2's sixteen change requests made by the teahouse owner in the workbench, in a real browser.

Why this module: the promise is that the owner changes the robots' behaviour alone, in the browser,
in under a minute, live. Each ``change_N`` function below is what the owner does for suggestion N
(clicks and fields filled in the workflow editor, the rules editor and the knowledge editor; no
YAML, DRL or Python typed for the workflow and knowledge changes); :func:`make_all` makes them in
the paper's order and, after each, checks on the running gateway with the probe of
:mod:`agile_harness` (tests/agile_harness.py: a workflow run's trace, a rule fire, Pellet's inference) that the
behaviour changed. It records the steps (counted by :class:`Owner`) and the seconds from starting
the change to the behaviour verified, and saves a screenshot per change.

Shared by the acceptance test (``tests/workbench/test_table2_browser.py``, on the session's
gateway) and the benchmark (``bench/table2_browser.py``, on a fresh gateway); nothing here starts
or stops a gateway.

Two suggestions need a rule set the teahouse does not have (#8 and #11: seat information in DRL).
The owner creates it in the workbench ("+ New rule set"); the engineer hands over three small rule
files (the ``Table`` fact type and the two rules), which the owner adds with "+ Add a file…" and
deploys. Writing those files is the engineer's part and is not counted.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import httpx
from playwright.sync_api import Locator, Page, expect

from agile_harness import DIRTY_TABLE_DRL as AGILE_DIRTY_TABLE_DRL
from agile_harness import (
    BLANKET_DSLR, SEAT_INFO_DRL, TABLES, Observation, OwnerClient, Scenario, scenarios,
)

EDITOR = ".editor-host:not([hidden]) .cm-content"
SAVED = re.compile(r"Saved: version \d+ is live")
DEPLOYED = re.compile(r"Version \d+ is now live")
LIVE_TIMEOUT_S = 10.0

# What the owner changes; restored by :func:`snapshot` / :func:`restore`.
WORKFLOWS = ("show_to_seat", "prepare_drinks", "take_order", "settle_bill", "greeting")
RULESETS = ("reception",)
KNOWLEDGE = ("ontology", "swrl")

# The engineer's files for #8/#11, cut from the agile scenarios' seat-info rules: the fact type,
# the free-tables rule, and the dirty-table rule (each file with the package header).
_HEADER, _RULES = SEAT_INFO_DRL.split("declare Table", 1)
_RULES = "declare Table" + _RULES
_TYPES_END = _RULES.index("end\n") + len("end\n")
_HEAD = _HEADER.split("// A table")[0]
SEAT_INFO_TYPES = _HEADER + _RULES[:_TYPES_END]
FREE_TABLES_DRL = _HEAD + _RULES[_TYPES_END:].lstrip("\n")
DIRTY_TABLE_DRL = _HEAD + AGILE_DIRTY_TABLE_DRL.lstrip("\n")


# ---------------------------------------------------------------- the owner's hands, counted


class Owner:
    """The owner at the browser: each click, field filled, choice made, key chord or file picked is
    one step (waiting for the page to answer is not)."""

    def __init__(self, page: Page, base_url: str) -> None:
        self.page = page
        self.base_url = base_url
        self.steps = 0
        self.log: list[str] = []

    def _did(self, what: str) -> None:
        self.steps += 1
        self.log.append(what)

    def open(self, path: str) -> None:
        """Open an item by its deep link (one click on a link or bookmark)."""
        self.page.goto(path)
        self._did(f"open {path}")

    def click(self, target: Locator, what: str = "") -> None:
        target.click()
        self._did(f"click {what}")

    def fill(self, target: Locator, value: str, what: str = "") -> None:
        target.fill(value)
        self._did(f"fill {what} = {value!r}")

    def select(self, target: Locator, value: str, what: str = "") -> None:
        target.select_option(value)
        self._did(f"choose {what} = {value!r}")

    def keys(self, chord: str) -> None:
        self.page.keyboard.press(chord)
        self._did(f"press {chord}")

    def paste(self, text: str) -> None:
        """Type (or paste) text at the cursor of the focused editor."""
        self.page.keyboard.insert_text(text)
        self._did(f"type {len(text)} characters")

    def upload(self, target: Locator, path: Path) -> None:
        target.set_input_files(str(path))
        self._did(f"add file {path.name}")


@dataclass
class Setup:
    """What the changes need besides the page: the engineer's files and the seat-info rule set's name."""

    files: Path
    seat_info: str = "seat_info"


@dataclass
class Done:
    """One change request as the owner made it."""

    id: int
    suggestion: str
    category: str
    paper_time: str
    how: str
    steps: int
    seconds: float
    screenshot: str
    before: Observation
    after: Observation
    log: list[str] = field(default_factory=list)


# ---------------------------------------------------------------- workflow editor


def open_workflow(owner: Owner, name: str) -> None:
    owner.open(f"/workbench/workflows/{name}")
    expect(owner.page.get_by_test_id("wf-status")).to_have_text("✓ No problems")


def step_button(page: Page, step_id: str) -> Locator:
    return page.locator(f"button.wf-step-main[data-step='{step_id}']")


def form(page: Page) -> Locator:
    return page.get_by_test_id("wf-form")


def where_new_steps_go(owner: Owner, where: str) -> None:
    owner.select(owner.page.get_by_label("Where new steps go"), where, "where new steps go")


def insert(owner: Owner, entry: str) -> None:
    owner.click(owner.page.get_by_role("button", name=entry), entry)


def field_(owner: Owner, name: str, value: str) -> None:
    owner.fill(form(owner.page).locator(f"[data-field='{name}']"), value, name)


def save_workflow(owner: Owner, comment: str) -> None:
    page = owner.page
    expect(page.get_by_test_id("wf-status")).to_have_text("✓ No problems")
    owner.fill(page.get_by_label("What did you change? (comment for the version)"), comment, "comment")
    owner.click(page.get_by_test_id("wf-save"), "Save")
    expect(page.get_by_test_id("wf-save-message")).to_contain_text(SAVED)


def say_step(owner: Owner, workflow: str, anchor: str, where: str, step_id: str, text: str, comment: str) -> None:
    """Pepper says ``text`` before/after step ``anchor``: the palette's "Pepper: say" and its form."""
    open_workflow(owner, workflow)
    owner.click(step_button(owner.page, anchor), f"step {anchor}")
    where_new_steps_go(owner, where)
    insert(owner, "Insert: Pepper: say")
    field_(owner, "with.text", text)
    field_(owner, "id", step_id)
    save_workflow(owner, comment)


def change_1(owner: Owner, setup: Setup) -> None:
    say_step(owner, "show_to_seat", "go_to_table", "before", "announce_move",
             "I will show you to your table. Please follow me.", "Table 2 #1: speak before moving")


def change_2(owner: Owner, setup: Setup) -> None:
    open_workflow(owner, "show_to_seat")
    owner.click(step_button(owner.page, "go_to_table"), "step go_to_table")
    where_new_steps_go(owner, "before")
    insert(owner, "Insert: Pepper: gesture")
    field_(owner, "with.name", "point to the table")
    field_(owner, "id", "point_the_way")
    save_workflow(owner, "Table 2 #2: point the way before moving")


def change_3(owner: Owner, setup: Setup) -> None:
    open_workflow(owner, "prepare_drinks")
    owner.click(owner.page.get_by_role("button", name="Add new steps at the end of the else arm of any_order"),
                "the else arm of any_order")
    insert(owner, "Insert: Jaco2: gesture / motion")  # the workflow's jaco2_motion module
    field_(owner, "with.name", "tea ceremony performance")
    field_(owner, "id", "idle_performance")
    save_workflow(owner, "Table 2 #3: perform while idle")


def change_4(owner: Owner, setup: Setup) -> None:
    say_step(owner, "show_to_seat", "go_to_table", "after", "invite_to_sit",
             "Here is your table. Please have a seat.", "Table 2 #4: invite them to sit")


def change_5(owner: Owner, setup: Setup) -> None:
    page = owner.page
    open_workflow(owner, "take_order")
    owner.click(step_button(page, "confirm_order"), "step confirm_order")
    where_new_steps_go(owner, "before")
    insert(owner, "Insert: Wait")  # no wait module yet: the palette adds one ("pause")
    field_(owner, "id", "let_them_finish")
    owner.click(page.get_by_role("button", name="Edit module pause"), "edit module pause")
    field_(owner, "params.seconds", "0.2")
    save_workflow(owner, "Table 2 #5: let them finish")


def change_6(owner: Owner, setup: Setup) -> None:
    say_step(owner, "take_order", "go_to_table", "before", "announce_visit",
             "Excuse me, I am coming to take your order.", "Table 2 #6: announce the visit")


def change_7(owner: Owner, setup: Setup) -> None:
    open_workflow(owner, "settle_bill")
    owner.click(step_button(owner.page, "settle_bill"), "step settle_bill")
    where_new_steps_go(owner, "before")
    insert(owner, "Insert: Pepper: move to")
    field_(owner, "with.x", "${input.table.x - 0.5}")
    field_(owner, "with.y", "${input.table.y}")
    field_(owner, "id", "go_to_table")
    where_new_steps_go(owner, "after")  # after the new go_to_table
    insert(owner, "Insert: Pepper: say")
    field_(owner, "with.text", "Thank you. Our staff will bring your bill now.")
    field_(owner, "id", "announce_bill")
    save_workflow(owner, "Table 2 #7: visit and speak before the bill")


# ---------------------------------------------------------------- rules editor


def open_ruleset(owner: Owner, name: str) -> None:
    owner.open(f"/workbench#/rules/{name}")
    expect(owner.page.get_by_test_id("check-status")).to_have_text("✓ No problems")


def add_rule_file(owner: Owner, path: Path) -> None:
    page = owner.page
    owner.upload(page.get_by_test_id("add-file"), path)  # what "+ Add a file…" opens
    expect(page.get_by_test_id("add-file-result")).to_contain_text(f"Added {path.name}")


def deploy(owner: Owner, comment: str) -> None:
    page = owner.page
    expect(page.get_by_test_id("check-status")).to_have_text("✓ No problems")
    owner.fill(page.get_by_label("What did you change?"), comment, "comment")
    owner.click(page.get_by_test_id("deploy"), "Deploy to the robot")
    expect(page.get_by_test_id("deploy-result")).to_contain_text(DEPLOYED)


def change_8(owner: Owner, setup: Setup) -> None:
    page = owner.page
    # the rules: a new rule set, the engineer's files added to it, deployed
    owner.open("/workbench#/rules/reception")
    owner.click(page.get_by_role("button", name="+ New rule set"), "+ New rule set")
    owner.fill(page.get_by_test_id("new-ruleset-name"), setup.seat_info, "name")
    owner.click(page.get_by_test_id("create-ruleset"), "Create")
    expect(page.locator("section.ruleset h1")).to_have_text(setup.seat_info)  # the new rule set is open
    expect(page.get_by_test_id("check-status")).to_have_text("✓ No problems")
    add_rule_file(owner, setup.files / "tables.drl")
    add_rule_file(owner, setup.files / "free_tables.drl")
    deploy(owner, "Table 2 #8: tell how many tables are free")
    # the workflow: fire them after the welcome
    open_workflow(owner, "greeting")
    owner.click(step_button(page, "reception_rules"), "step reception_rules")
    insert(owner, "Insert: Fire business rules")
    field_(owner, "with.facts", "${input.tables}")
    field_(owner, "id", "seat_info_rules")
    owner.click(page.get_by_role("button", name="Edit module fire_rules"), "edit module fire_rules")
    owner.select(form(page).locator("[data-field=ruleset]"), setup.seat_info, "rule set")
    owner.fill(form(page).get_by_label("Rule action (e.g. say)"), "say", "rule action")
    owner.select(form(page).get_by_label("Module that performs it"), "say", "module")
    owner.click(form(page).get_by_role("button", name="Add action"), "Add action")
    expect(form(page)).to_contain_text("say → say")
    save_workflow(owner, "Table 2 #8: tell the free tables after the welcome")


def change_9(owner: Owner, setup: Setup) -> None:
    """Every 'bow' of the greetings becomes a deep bow: Replace… beside the rule list, Replace all."""
    page = owner.page
    open_ruleset(owner, "reception")
    owner.click(page.get_by_role("button", name="Replace…"), "Replace…")
    owner.fill(page.get_by_label("Find", exact=True), '"bow"', "find")
    owner.fill(page.get_by_label("Replace with", exact=True), '"deep bow with open arms"', "replace with")
    owner.click(page.get_by_role("button", name="Replace all"), "Replace all")
    expect(page.get_by_role("status").filter(has_text="Replaced 6 places")).to_be_visible()
    expect(page.get_by_test_id("check-status")).to_have_text("✓ No problems")
    deploy(owner, "Table 2 #9: a deep bow with open arms")


def change_10(owner: Owner, setup: Setup) -> None:
    """A new rule in the owner's sentences, typed at the end of the reception rules."""
    page = owner.page
    open_ruleset(owner, "reception")
    owner.click(page.locator(EDITOR), "the sentences")
    owner.keys("Control+End")
    owner.paste(BLANKET_DSLR)
    expect(page.locator(EDITOR)).to_contain_text('Pepper says "Would you like a blanket for your legs?"')
    deploy(owner, "Table 2 #10: offer blankets")


def change_11(owner: Owner, setup: Setup) -> None:
    open_ruleset(owner, setup.seat_info)
    add_rule_file(owner, setup.files / "dirty_table.drl")
    deploy(owner, "Table 2 #11: say that a dirty table is being cleaned")


# ---------------------------------------------------------------- knowledge editor


def set_value(owner: Owner, name: str, value: str, comment: str) -> None:
    """Type a number into the value cell, say why, save; the view confirms it is live."""
    page = owner.page
    owner.fill(page.get_by_test_id(f"value-{name}"), value, name)
    owner.fill(page.get_by_label(f"Comment for {name}"), comment, "comment")
    owner.click(page.get_by_test_id(f"save-{name}"), "Save")
    expect(page.get_by_test_id("values-message")).to_contain_text(f"✓ {name} = {value} is live")


def open_knowledge(owner: Owner, item: str) -> None:
    owner.open(f"/workbench/knowledge/{item}")
    expect(owner.page.get_by_role("heading", name=f"Knowledge · {item}")).to_be_visible()


def change_12(owner: Owner, setup: Setup) -> None:
    open_knowledge(owner, "pepper1")
    set_value(owner, "pepper1.robotToHumanDistance", "1.5", "Table 2 #12: stand further from the party")


def change_13(owner: Owner, setup: Setup) -> None:
    open_knowledge(owner, "pepper1")
    set_value(owner, "pepper1.robotToTableDistance", "0.8", "Table 2 #13: stop further from the table")


def change_14(owner: Owner, setup: Setup) -> None:
    page = owner.page
    owner.open("/workbench/knowledge")
    owner.click(page.locator("[data-class=Serving]"), "class Serving")  # found through the class tree
    expect(page.get_by_role("heading", name="Knowledge · Serving")).to_be_visible()
    set_value(owner, "serving1.emptyCupReactionTime", "15", "Table 2 #14: react sooner to empty cups")


def edit_swrl_rule(owner: Owner, number: int, old: str, new: str, comment: str) -> None:
    """Edit the number in SWRL rule ``number``, let Pellet check it, save it."""
    page = owner.page
    owner.open(f"/workbench/knowledge/rules/{number}")
    owner.click(page.get_by_test_id(f"edit-{number}"), f"Edit rule {number}")
    area = page.get_by_test_id(f"rule-text-{number}")
    text = area.input_value()
    assert text.count(old) == 1, f"rule {number}: {old!r} not found once in {text!r}"
    owner.fill(area, text.replace(old, new), f"rule {number}")
    owner.fill(page.get_by_label(f"Comment for rule {number}"), comment, "comment")
    owner.click(page.get_by_test_id(f"check-{number}"), "Check")
    expect(page.get_by_test_id(f"verdict-{number}")).to_contain_text("✓ Pellet: consistent")
    owner.click(page.get_by_test_id(f"save-rule-{number}"), "Save")
    expect(page.get_by_test_id("rules-message")).to_contain_text(f"✓ Rule {number} saved and live")


def change_15(owner: Owner, setup: Setup) -> None:
    edit_swrl_rule(owner, 6, "lessThan(?a, 7)", "lessThan(?a, 6)", "Table 2 #15: child seats below 6")


def change_16(owner: Owner, setup: Setup) -> None:
    edit_swrl_rule(owner, 7, "0.8)", "0.7)", "Table 2 #16: pour a little less")


CHANGES: dict[int, tuple[str, Callable[[Owner, Setup], None]]] = {
    1: ("workflow editor: Pepper: say before go_to_table", change_1),
    2: ("workflow editor: Pepper: gesture before go_to_table", change_2),
    3: ("workflow editor: a Jaco2 motion in the else arm", change_3),
    4: ("workflow editor: Pepper: say after go_to_table", change_4),
    5: ("workflow editor: a Wait step (0.2 s) before confirm_order", change_5),
    6: ("workflow editor: Pepper: say before go_to_table", change_6),
    7: ("workflow editor: move to + say before settle_bill", change_7),
    8: ("rules: + New rule set seat_info, add the engineer's files*, deploy; workflow editor: Fire business rules",
        change_8),
    9: ("rules: Replace… (\"bow\" → \"deep bow with open arms\"), Replace all, deploy", change_9),
    10: ("rules editor: a new rule in sentences (DSL), deploy", change_10),
    11: ("rules: add the engineer's file to seat_info*, deploy", change_11),
    12: ("knowledge editor: a value of pepper1", change_12),
    13: ("knowledge editor: a value of pepper1", change_13),
    14: ("knowledge editor: class tree → Serving, a value", change_14),
    15: ("knowledge editor: SWRL rule 6, Pellet check, save", change_15),
    16: ("knowledge editor: SWRL rule 7, Pellet check, save", change_16),
}


def show_a_deep_bow(page: Page) -> None:
    """For #9's screenshot: the rule list searched for the new words, the editor at the first (not one
    of the owner's steps)."""
    page.get_by_test_id("rule-search").fill("deep bow with open arms")


def show_the_saved_value(page: Page) -> None:
    """For #12-#14's screenshots: the page's top, with the confirmation that the value is live."""
    page.evaluate("window.scrollTo(0, 0)")


FRAMES: dict[int, Callable[[Page], None]] = {9: show_a_deep_bow, 12: show_the_saved_value,
                                             13: show_the_saved_value, 14: show_the_saved_value}


# ---------------------------------------------------------------- preparing, making, restoring


def prepare(client: httpx.Client, setup: Setup) -> None:
    """The engineer's part for #8/#11: three small rule files (the owner creates the rule set)."""
    setup.files.mkdir(parents=True, exist_ok=True)
    (setup.files / "tables.drl").write_text(SEAT_INFO_TYPES, encoding="utf-8")
    (setup.files / "free_tables.drl").write_text(FREE_TABLES_DRL, encoding="utf-8")
    (setup.files / "dirty_table.drl").write_text(DIRTY_TABLE_DRL, encoding="utf-8")


def verified(gw: OwnerClient, scenario: Scenario) -> Observation:
    """The probe's observation once it shows the new behaviour (bounded wait)."""
    deadline = time.monotonic() + LIVE_TIMEOUT_S
    seen = scenario.probe(gw)
    while not scenario.expect(seen):
        assert time.monotonic() < deadline, f"#{scenario.id}: not live within {LIVE_TIMEOUT_S}s; now: {seen}"
        time.sleep(0.05)
        seen = scenario.probe(gw)
    return seen


def make_all(page: Page, gw: OwnerClient, setup: Setup, shots: Path,
             only: set[int] | None = None) -> list[Done]:
    """Make the change requests in Table 2 order; each: old behaviour checked, the owner's steps,
    new behaviour verified, screenshot saved."""
    page.set_viewport_size({"width": 1280, "height": 800})
    shots.mkdir(parents=True, exist_ok=True)
    done = []
    for scenario in scenarios():
        if only and scenario.id not in only:
            continue
        how, change = CHANGES[scenario.id]
        before = scenario.probe(gw)
        assert not scenario.expect(before), f"#{scenario.id}: already changed before the edit: {before}"
        owner = Owner(page, gw.http.base_url)
        started = time.perf_counter()
        change(owner, setup)
        after = verified(gw, scenario)
        seconds = time.perf_counter() - started
        if scenario.id in FRAMES:
            FRAMES[scenario.id](page)
        shot = shots / f"{scenario.id:02d}.png"
        page.screenshot(path=str(shot))
        done.append(Done(scenario.id, scenario.suggestion, scenario.category, scenario.paper_time, how,
                         owner.steps, round(seconds, 1), shot.name, before, after, owner.log))
    return done


def snapshot(client: httpx.Client) -> dict[str, dict[str, int]]:
    """The live versions of what the changes touch."""
    return {
        "workflows": {n: client.get(f"/api/workflows/{n}").json()["version"] for n in WORKFLOWS},
        "rulesets": {n: _ruleset_version(client, n) for n in RULESETS},
        "knowledge": {k: client.get(f"/api/knowledge/{k}").json()["version"] for k in KNOWLEDGE},
    }


def _ruleset_version(client: httpx.Client, name: str) -> int:
    body = client.get(f"/api/rulesets/{name}").json()
    return (body.get("info") or body)["version"]


def restore(client: httpx.Client, was: dict[str, dict[str, int]], setup: Setup) -> None:
    """Roll back everything the changes touched to the versions of ``was``; drop seat_info."""
    now = snapshot(client)
    paths = {"workflows": "/api/workflows/{}/rollback", "rulesets": "/api/rulesets/{}/rollback",
             "knowledge": "/api/knowledge/{}/rollback"}
    for group, versions in was.items():
        for name, version in versions.items():
            if now[group][name] != version:
                answer = client.post(paths[group].format(name), json={"version": version, "comment": "Table 2 undone"})
                assert answer.status_code in (200, 201), answer.text
    client.delete(f"/api/rulesets/{setup.seat_info}")


def markdown(done: list[Done], image_dir: str = "img/table2") -> str:
    """The table for docs/agile-loop.md."""
    rows = ["| ID | Change | Kind | Paper (m:ss) | How, in the browser | Our steps | Our seconds | Screenshot |",
            "|---:|---|---|---:|---|---:|---:|---|"]
    for d in done:
        rows.append(f"| {d.id} | {d.suggestion} | {d.category} | {d.paper_time} | {d.how} | {d.steps} | "
                    f"{d.seconds:.1f} | [{d.screenshot}]({image_dir}/{d.screenshot}) |")
    total_steps = sum(d.steps for d in done)
    total_s = sum(d.seconds for d in done)
    rows.append(f"| | **all {len(done)}** | | | | **{total_steps}** | **{total_s:.1f}** | |")
    return "\n".join(rows)


def steps_markdown(done: list[Done]) -> str:
    """Every change's steps, one line each, as the owner made them (folded)."""
    out = ["<details><summary>The owner's steps, change by change</summary>", ""]
    for d in done:
        out.append(f"**#{d.id}** ({d.steps} steps): " + " · ".join(f"`{step}`" for step in d.log))
        out.append("")
    out.append("</details>")
    return "\n".join(out)
