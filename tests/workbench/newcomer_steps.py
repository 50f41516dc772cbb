"""Table 2's sixteen changes made by a newcomer who only reads the screen (issue 31, item 5).

Why this module: the scripted run (:mod:`table2_steps`) proves each change can be made in the
browser, but it reaches controls by test ids and deep links and used the editor's Ctrl+F. A
newcomer has neither: they read the top bar, the list on the left, the headings, labels and
buttons, and click or type into what those words name. Here every control is found by the text a
person sees (a link's or button's words, a field's label, a menu's options) — no test ids, no CSS
selectors, no URLs typed, no keyboard shortcuts, no ``force``, and nothing typed but the sentence,
name or value being changed (exceptions, documented in docs/agile-loop.md: #8b's facts are typed as
``${input.tables}``, a run input the greeting workflow does not declare; #8a/#11 add the engineer's
rule files with "+ Add a file…"). A menu is read from the top down to the option chosen; a grouped
menu by its group headings, and the chosen group's options down to the one chosen.

Each step is priced with a keystroke-level model (Card, Moran & Newell, "The Keystroke-Level
Model", CACM 1980), plus the reading the step needs:

* every action (click, menu choice, field typed into) starts with a mental preparation of
  :data:`MENTAL_S` and a point-and-click of :data:`CLICK_S`; a menu choice is two clicks;
* each character typed costs :data:`TYPE_S_PER_CHAR` (a non-secretary typist);
* the words the step has to read — the text of the control it looks for and of every answer it
  checks (a confirmation, a list of matches, Pellet's verdict) — are read at
  :data:`WORDS_PER_MINUTE`;
* each new screen (a section, a workflow, a rule set, a knowledge page opened) costs at least
  :data:`SCREEN_S` to take in (the issue's "2 s per screen").

The sum is the change's estimated time for a person; :data:`ONE_MINUTE` is the bound the test
asserts. The machine's own seconds (the browser and the gateway working) are recorded beside it.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from playwright.sync_api import Locator, Page, expect

from agile_harness import Observation, OwnerClient, scenarios
from table2_steps import Setup, verified

WORDS_PER_MINUTE = 200  # reading on screen (adults read 200-260 wpm; the lower end for a newcomer)
SCREEN_S = 2.0          # taking in a new screen: the 2 s per screen
CLICK_S = 1.2           # KLM: point with the mouse (1.1 s) and press the button (0.1 s)
MENTAL_S = 1.35         # KLM: mental preparation before each action
TYPE_S_PER_CHAR = 0.28  # KLM: an average non-secretary typist
ONE_MINUTE = 60.0
#: Version comments are optional everywhere; the newcomer's shortest path leaves them out (a short
#: comment adds about 8 s: one field, ~20 characters).
WITH_COMMENTS = False

DEPLOYED = re.compile(r"Version \d+ is now live")
SAVED = re.compile(r"Saved: version \d+ is live")
READ_JS = """e => {
  const label = e.labels && e.labels.length ? e.labels[0].innerText : "";
  const own = e.tagName === "SELECT" || e.tagName === "INPUT" || e.tagName === "TEXTAREA" ? "" : e.innerText || "";
  return [label, own].join(" ").trim() || e.getAttribute("aria-label") || e.placeholder || "";
}"""
OPTIONS_UP_TO_JS = """(e, chosen) => {
  // A menu read from the top down to the chosen option; in a grouped menu, the group headings down
  // to the chosen option's group, and only that group's options (a reader skips the other groups).
  const chosenOption = [...e.options].find((o) => o.text === chosen);
  const chosenGroup = chosenOption && chosenOption.parentElement.tagName === "OPTGROUP" ? chosenOption.parentElement : null;
  const read = [];
  for (const child of e.children) {
    if (child.tagName === "OPTGROUP") {
      read.push(child.label);
      if (child === chosenGroup) {
        for (const o of child.children) { read.push(o.text); if (o === chosenOption) return read.join(" "); }
      }
    } else {
      read.push(child.text);
      if (child === chosenOption) return read.join(" ");
    }
  }
  return read.join(" ");
}"""


def words(text: str) -> int:
    return len(text.split())


class Newcomer:
    """A person at the browser who finds every control by its words. Counts what they do and read."""

    def __init__(self, page: Page) -> None:
        self.page = page
        self.actions = 0
        self.clicks = 0
        self.typed = 0
        self.words = 0
        self.screens = 0
        self.log: list[str] = []

    # ---- what they read

    def read(self, target: Locator, what: str = "") -> str:
        """Read an element's visible words (an answer, a list, a confirmation)."""
        text = target.inner_text()
        self.words += words(text)
        if what:
            self.log.append(f"read {what}")
        return text

    def _read_control(self, target: Locator) -> None:
        self.words += words(target.evaluate(READ_JS))

    def new_screen(self) -> None:
        self.screens += 1

    # ---- what they do

    def click(self, target: Locator, what: str) -> None:
        expect(target).to_be_visible()
        self._read_control(target)
        target.click()
        self.actions += 1
        self.clicks += 1
        self.log.append(f"click “{what}”")

    def choose(self, menu: Locator, option: str, what: str) -> None:
        """Open a menu and pick the option with these words (two clicks); the menu is read from the
        top down to that option."""
        expect(menu).to_be_visible()
        self._read_control(menu)
        self.words += words(menu.evaluate(OPTIONS_UP_TO_JS, option))
        menu.select_option(label=option)
        self.actions += 1
        self.clicks += 2
        self.log.append(f"choose “{option}” in “{what}”")

    def type_into(self, target: Locator, text: str, what: str) -> None:
        """Click into a field and type ``text`` (an empty field, or all of it replaced)."""
        expect(target).to_be_visible()
        self._read_control(target)
        target.fill(text)
        self.actions += 1
        self.clicks += 1
        self.typed += len(text)
        self.log.append(f"type {text!r} into “{what}”")

    def retype_part(self, area: Locator, around: str, old: str, new: str, what: str) -> None:
        """Double-click the word ``old`` (where it stands in ``around``) in a text area and type
        ``new`` over it; the rest of the text is untouched."""
        expect(area).to_be_visible()
        text = area.input_value()
        assert text.count(around) == 1 and old in around, f"{what}: {around!r} is not in the text once: {text!r}"
        start = text.index(around) + around.index(old)
        area.evaluate("(e, [a, b]) => { e.focus(); e.setSelectionRange(a, b); }", [start, start + len(old)])
        self.page.keyboard.insert_text(new)  # typing characters, no shortcut
        self.actions += 1
        self.clicks += 2  # a double-click on the word
        self.typed += len(new)
        self.log.append(f"double-click {old!r} in “{what}”, type {new!r}")

    def add_file(self, button: Locator, path: Path) -> None:
        """Press a button that opens the file chooser and pick a file (two clicks)."""
        self._read_control(button)
        with self.page.expect_file_chooser() as chooser:
            button.click()
        chooser.value.set_files(str(path))
        self.actions += 1
        self.clicks += 2
        self.words += words(path.name)
        self.log.append(f"click “{button.inner_text().strip()}”, pick {path.name}")

    # ---- the estimate

    def seconds(self) -> float:
        """A person's time for what was done and read (the model in the module docstring)."""
        return (self.actions * MENTAL_S + self.clicks * CLICK_S + self.typed * TYPE_S_PER_CHAR
                + self.words * 60.0 / WORDS_PER_MINUTE + self.screens * SCREEN_S)


# ---------------------------------------------------------------- finding places by their words


def section(who: Newcomer, name: str) -> None:
    """A section of the top bar (Rules, Workflows, Knowledge…)."""
    page = who.page
    who.click(page.get_by_role("navigation", name="Sections").get_by_role("link", name=name, exact=True), name)
    who.new_screen()


def sidebar_link(page: Page, words_: str | re.Pattern[str]) -> Locator:
    return page.locator("aside.sidebar").get_by_role("link", name=words_)


def open_workflow(who: Newcomer, name: str) -> None:
    """Workflows, then the workflow in the list on the left (each names its file: "show_to_seat · version 3")."""
    page = who.page
    section(who, "Workflows")
    who.click(sidebar_link(page, re.compile(rf"\b{re.escape(name)} · version")), name)
    who.new_screen()
    expect(page.get_by_role("status").filter(has_text="No problems")).to_be_visible()


def open_ruleset(who: Newcomer, name: str) -> None:
    page = who.page
    section(who, "Rules")
    who.click(sidebar_link(page, re.compile(rf"^{re.escape(name)}(?![\w-])")), name)  # not "reception-tests-…"
    who.new_screen()
    expect(page.get_by_text("✓ No problems")).to_be_visible()


def step(page: Page, step_id: str) -> Locator:
    """A step of the process, by the name it shows."""
    return page.get_by_role("button", name=re.compile(rf"^Step {re.escape(step_id)}:"))


def form(page: Page) -> Locator:
    return page.get_by_role("region", name="Edit")


def palette(page: Page) -> Locator:
    return page.get_by_role("region", name="Palette")


def say_where(who: Newcomer, where: str) -> None:
    who.choose(who.page.get_by_label("Where new steps go"), {"before": "before the selected step",
                                                              "after": "after the selected step"}[where],
               "New steps go")


def insert(who: Newcomer, entry: str) -> None:
    who.click(palette(who.page).get_by_role("button", name=f"Insert: {entry}"), entry)


def fill_field(who: Newcomer, label: str, value: str) -> None:
    """The form's field with this label (a required one shows "label *")."""
    who.type_into(form(who.page).get_by_role("textbox", name=label, exact=True), value, label)


def save_workflow(who: Newcomer, comment: str) -> None:
    """Save and make live (the version comment is optional: see :data:`WITH_COMMENTS`)."""
    page = who.page
    expect(page.get_by_role("status").filter(has_text="No problems")).to_be_visible()
    if WITH_COMMENTS:
        who.type_into(page.get_by_label("Comment"), comment, "Comment")
    who.click(page.get_by_role("button", name="Save and make live"), "Save and make live")
    message = page.get_by_text(SAVED)
    expect(message).to_be_visible()
    who.read(message, "the confirmation")


def deploy(who: Newcomer, comment: str) -> None:
    """Deploy to the robot (the comment is optional: see :data:`WITH_COMMENTS`)."""
    page = who.page
    expect(page.get_by_text("✓ No problems")).to_be_visible()
    if WITH_COMMENTS:
        who.type_into(page.get_by_label("What did you change?"), comment, "What did you change?")
    who.click(page.get_by_role("button", name="Deploy to the robot"), "Deploy to the robot")
    message = page.get_by_text(DEPLOYED)
    expect(message).to_be_visible()
    who.read(message, "the confirmation")


# ---------------------------------------------------------------- the sixteen changes


def say_step(who: Newcomer, workflow: str, anchor: str, where: str, text: str, comment: str) -> None:
    """Pepper says ``text`` before/after a step (the new step keeps the name the palette gives it)."""
    open_workflow(who, workflow)
    who.click(step(who.page, anchor), f"step {anchor}")
    say_where(who, where)
    insert(who, "Pepper: say")
    fill_field(who, "text", text)
    save_workflow(who, comment)


def change_1(who: Newcomer, setup: Setup) -> None:
    say_step(who, "show_to_seat", "go_to_table", "before", "I will show you to your table. Please follow me.",
             "speak before moving")


def change_2(who: Newcomer, setup: Setup) -> None:
    open_workflow(who, "show_to_seat")
    who.click(step(who.page, "go_to_table"), "step go_to_table")
    say_where(who, "before")
    insert(who, "Pepper: gesture")
    fill_field(who, "name", "point to the table")
    save_workflow(who, "point the way")


def change_3(who: Newcomer, setup: Setup) -> None:
    page = who.page
    open_workflow(who, "prepare_drinks")
    who.click(page.get_by_role("button", name="Add new steps at the end of the else arm of any_order"),
              "+ add (else arm of any_order)")
    insert(who, "Jaco2: gesture / motion")
    fill_field(who, "name", "tea ceremony performance")
    save_workflow(who, "perform while idle")


def change_4(who: Newcomer, setup: Setup) -> None:
    say_step(who, "show_to_seat", "go_to_table", "after", "Here is your table. Please have a seat.",
             "invite them to sit")


def change_5(who: Newcomer, setup: Setup) -> None:
    page = who.page
    open_workflow(who, "take_order")
    who.click(step(page, "confirm_order"), "step confirm_order")
    say_where(who, "before")
    insert(who, "Wait")
    who.click(palette(page).get_by_role("button", name="Edit module pause"), "edit (module pause)")
    fill_field(who, "seconds", "0.2")
    save_workflow(who, "let them finish")


def change_6(who: Newcomer, setup: Setup) -> None:
    say_step(who, "take_order", "go_to_table", "before", "Excuse me, I am coming to take your order.",
             "announce the visit")


def change_7(who: Newcomer, setup: Setup) -> None:
    """Before settle_bill: Pepper goes to the bill's table and speaks. "+ add at the start" of the
    process takes the move; its place is picked from what the run is given ("the table (table1)");
    the say step goes after it (new steps go after the selected one)."""
    page = who.page
    open_workflow(who, "settle_bill")
    who.click(page.get_by_role("button", name="Add new steps at the start of the process settle"),
              "+ add at the start of the process settle")
    insert(who, "Pepper: move to")
    who.choose(form(page).get_by_label("Pick a value for location"), "the table (table1)", "Pick a value for location")
    uses = form(page).get_by_text("Uses the table (table1).")
    expect(uses).to_be_visible()
    insert(who, "Pepper: say")
    fill_field(who, "text", "Thank you. Our staff will bring your bill now.")
    save_workflow(who, "visit before the bill")


def change_8_rules(who: Newcomer, setup: Setup) -> None:
    """#8, the rules (the paper's 16:22): a new rule set with the engineer's two files, deployed."""
    page = who.page
    section(who, "Rules")
    who.click(page.get_by_role("button", name="+ New rule set"), "+ New rule set")
    who.type_into(page.get_by_label("Name of the new rule set"), setup.seat_info, "Name of the new rule set")
    who.click(page.get_by_role("button", name="Create", exact=True), "Create")
    who.new_screen()
    expect(page.get_by_role("heading", name=setup.seat_info, exact=True)).to_be_visible()
    expect(page.get_by_text("✓ No problems")).to_be_visible()
    for name in ("tables.drl", "free_tables.drl"):
        who.add_file(page.get_by_role("button", name="+ Add a file…"), setup.files / name)
        expect(page.get_by_text(f"Added {name}")).to_be_visible()
    deploy(who, "tell how many tables are free")


def change_8_workflow(who: Newcomer, setup: Setup) -> None:
    """#8, the workflow (the paper's 5:38): fire the new rule set after the welcome; its say actions
    go to Pepper's say."""
    page = who.page
    open_workflow(who, "greeting")
    who.click(step(page, "reception_rules"), "step reception_rules")
    insert(who, "Fire business rules")
    fill_field(who, "facts", "${input.tables}")
    who.click(palette(page).get_by_role("button", name="Edit module fire_rules"), "edit (module fire_rules)")
    who.choose(form(page).get_by_role("combobox", name="ruleset", exact=True), setup.seat_info, "ruleset")
    who.type_into(form(page).get_by_label("Rule action (e.g. say)"), "say", "Rule action")
    who.choose(form(page).get_by_label("Module that performs it"), "say", "Module that performs it")
    who.click(form(page).get_by_role("button", name="Add action"), "Add action")
    expect(form(page)).to_contain_text("say → say")
    save_workflow(who, "tell the free tables after the welcome")


def change_9(who: Newcomer, setup: Setup) -> None:
    """Every greeting's "bow" becomes a deep bow: Replace…, read where, Replace all."""
    page = who.page
    open_ruleset(who, "reception")
    who.click(page.get_by_role("button", name="Replace…"), "Replace…")
    who.type_into(page.get_by_label("Find", exact=True), '"bow"', "Find")
    found = page.get_by_role("region", name="Replace words in the rules")
    expect(found).to_contain_text("Found in 6 places")
    who.read(found.get_by_role("list"), "where it is found")
    who.type_into(page.get_by_label("Replace with", exact=True), '"deep bow with open arms"', "Replace with")
    who.click(page.get_by_role("button", name="Replace all"), "Replace all")
    who.read(page.get_by_role("status").filter(has_text="Replaced 6 places"), "the confirmation")
    deploy(who, "a deep bow with open arms")


def change_10(who: Newcomer, setup: Setup) -> None:
    """A new rule from sentences chosen in grouped menus ("Most used" first); the party the condition
    is about comes with it; the rule is named after what it does; only what Pepper says is typed."""
    page = who.page
    open_ruleset(who, "reception")
    who.click(page.get_by_role("button", name="+ New rule", exact=True), "+ New rule")
    who.choose(page.get_by_label("Add a condition"), "Everyone in the party has a type", "Add a condition")
    when = page.get_by_role("list", name="When")
    expect(when).to_contain_text("There is a party at the entrance")  # brought along: the sentence is about it
    who.choose(page.get_by_label("Add an action"), 'Pepper says "…"', "Add an action")
    who.type_into(page.get_by_label('text in: Pepper says "…"'), "Would you like a blanket for your legs?", "text")
    who.click(page.get_by_role("button", name="Add the rule and deploy"), "Add the rule and deploy")
    message = page.get_by_text(DEPLOYED)
    expect(message).to_be_visible(timeout=120_000)  # the build starts before the editor's check has warmed it
    who.read(message, "the confirmation")
    expect(page.get_by_role("button", name=re.compile("Pepper says “Would you like a blanket"))).to_be_visible()


def change_11(who: Newcomer, setup: Setup) -> None:
    page = who.page
    open_ruleset(who, setup.seat_info)
    who.add_file(page.get_by_role("button", name="+ Add a file…"), setup.files / "dirty_table.drl")
    expect(page.get_by_text("Added dirty_table.drl")).to_be_visible()
    deploy(who, "say that a dirty table is being cleaned")


def open_knowledge_item(who: Newcomer, item: str) -> None:
    """Knowledge, then the item in the class tree on the left."""
    section(who, "Knowledge")
    who.click(sidebar_link(who.page, re.compile(rf"^{re.escape(item)}\b")), item)
    who.new_screen()
    expect(who.page.get_by_role("heading", name=f"Knowledge · {item}")).to_be_visible()


def set_value(who: Newcomer, name: str, value: str, comment: str) -> None:
    """The value's field (labelled with its name and unit), why, Save; read that it is live."""
    page = who.page
    who.type_into(page.get_by_label(re.compile(rf"^{re.escape(name)} \(")), value, name)
    if WITH_COMMENTS:
        who.type_into(page.get_by_label(f"Comment for {name}"), comment, "why?")
    row = page.get_by_role("row").filter(has=page.get_by_label(f"Comment for {name}"))
    who.click(row.get_by_role("button", name="Save"), "Save")
    message = page.get_by_text(f"✓ {name} = {value} is live")
    expect(message).to_be_visible()
    who.read(message, "the confirmation")


def change_12(who: Newcomer, setup: Setup) -> None:
    open_knowledge_item(who, "pepper1")
    set_value(who, "pepper1.robotToHumanDistance", "1.5", "stand further from the party")


def change_13(who: Newcomer, setup: Setup) -> None:
    open_knowledge_item(who, "pepper1")
    set_value(who, "pepper1.robotToTableDistance", "0.8", "stop further from the table")


def change_14(who: Newcomer, setup: Setup) -> None:
    open_knowledge_item(who, "Serving")
    set_value(who, "serving1.emptyCupReactionTime", "15", "react sooner to empty cups")


def edit_swrl_rule(who: Newcomer, number: int, around: str, old: str, new: str, comment: str) -> None:
    """SWRL rules, the rule's Edit, its number retyped, Check (read Pellet's verdict), Save."""
    page = who.page
    section(who, "Knowledge")
    who.click(sidebar_link(page, "SWRL rules"), "SWRL rules")
    who.new_screen()
    card = page.get_by_role("listitem").filter(has=page.get_by_text(f"Rule {number}", exact=True))
    who.read(card.locator("p"), f"rule {number} in words")
    who.click(card.get_by_role("button", name="Edit"), f"Edit (rule {number})")
    who.retype_part(page.get_by_label(f"Rule {number} text"), around, old, new, f"rule {number}")
    if WITH_COMMENTS:
        who.type_into(page.get_by_label(f"Comment for rule {number}"), comment, "why?")
    who.click(card.get_by_role("button", name="Check"), "Check")
    verdict = card.get_by_text("✓ Pellet: consistent")
    expect(verdict).to_be_visible()
    who.read(verdict, "Pellet's verdict")
    who.click(card.get_by_role("button", name="Save"), "Save")
    message = page.get_by_text(f"✓ Rule {number} saved and live")
    expect(message).to_be_visible()
    who.read(message, "the confirmation")


def change_15(who: Newcomer, setup: Setup) -> None:
    edit_swrl_rule(who, 6, "lessThan(?a, 7)", "7", "6", "child seats below 6")


def change_16(who: Newcomer, setup: Setup) -> None:
    edit_swrl_rule(who, 7, "0.8)", "0.8", "0.7", "pour a little less")


Part = tuple[str, str, Callable[[Newcomer, Setup], None]]  # label ("8a"), what is done, how

CHANGES: dict[int, tuple[str, Callable[[Newcomer, Setup], None]] | list[Part]] = {
    1: ("Workflows → show_to_seat → step go_to_table → before → Pepper: say, its text → Save", change_1),
    2: ("Workflows → show_to_seat → step go_to_table → before → Pepper: gesture, its name → Save", change_2),
    3: ("Workflows → prepare_drinks → + add (else arm) → Jaco2: gesture / motion, its name → Save", change_3),
    4: ("Workflows → show_to_seat → step go_to_table → after → Pepper: say, its text → Save", change_4),
    5: ("Workflows → take_order → step confirm_order → before → Wait → edit module: seconds → Save", change_5),
    6: ("Workflows → take_order → step go_to_table → before → Pepper: say, its text → Save", change_6),
    7: ("Workflows → settle_bill → + add at the start → Pepper: move to, location picked (the table) → Pepper: say, "
        "its text → Save", change_7),
    8: [("8a", "Rules → + New rule set, its name → + Add a file… ×2* → Deploy", change_8_rules),
        ("8b", "Workflows → greeting → step reception_rules → Fire business rules, facts† → edit module: rule set, "
               "action say → say → Save", change_8_workflow)],
    9: ("Rules → reception → Replace… “\"bow\"” → Replace all → Deploy", change_9),
    10: ("Rules → reception → + New rule: a condition and an action from grouped menus, the sentence → Add the rule "
         "and deploy", change_10),
    11: ("Rules → seat_info → + Add a file…* → Deploy", change_11),
    12: ("Knowledge → pepper1 → the value, why → Save", change_12),
    13: ("Knowledge → pepper1 → the value, why → Save", change_13),
    14: ("Knowledge → Serving → the value, why → Save", change_14),
    15: ("Knowledge → SWRL rules → Edit rule 6 → the number → Check → Save", change_15),
    16: ("Knowledge → SWRL rules → Edit rule 7 → the number → Check → Save", change_16),
}


@dataclass
class Made:
    """One change as the newcomer made it, with its estimate for a person."""

    id: str  # "1".."16"; "8a"/"8b" for #8's two parts
    suggestion: str
    paper_time: str
    how: str
    actions: int
    clicks: int
    typed: int
    words: int
    screens: int
    person_s: float
    machine_s: float
    screenshot: str
    before: Observation
    after: Observation
    log: list[str] = field(default_factory=list)


def _perform(page: Page, part: Callable[[Newcomer, Setup], None], setup: Setup) -> tuple[Newcomer, float]:
    """One change (or part of one) from the workbench's front page: the newcomer and the machine's seconds."""
    page.goto("/workbench")  # where the newcomer starts: the front page
    who = Newcomer(page)
    who.new_screen()
    started = time.perf_counter()
    part(who, setup)
    return who, time.perf_counter() - started


def make_all(page: Page, gw: OwnerClient, setup: Setup, shots: Path) -> list[Made]:
    """The sixteen changes in Table 2's order; each checked on the running gateway before (old
    behaviour) and after (new behaviour). #8, which the paper timed as two parts (rules, then
    workflow), is made and estimated as those two parts."""
    page.set_viewport_size({"width": 1280, "height": 800})
    shots.mkdir(parents=True, exist_ok=True)
    made = []
    for scenario in scenarios():
        entry = CHANGES[scenario.id]
        parts = entry if isinstance(entry, list) else [(str(scenario.id), entry[0], entry[1])]
        before = scenario.probe(gw)
        assert not scenario.expect(before), f"#{scenario.id}: already changed before the edit: {before}"
        done = []
        for label, how, part in parts:
            started = time.perf_counter()
            who, machine = _perform(page, part, setup)
            if part is parts[-1][2]:
                after = verified(gw, scenario)
                machine = time.perf_counter() - started
            shot = shots / f"{label.zfill(2 if label.isdigit() else 3)}.png"
            page.screenshot(path=str(shot))
            done.append((label, how, who, machine, shot))
        for label, how, who, machine, shot in done:
            made.append(Made(label, scenario.suggestion, scenario.paper_time, how, who.actions, who.clicks, who.typed,
                             who.words, who.screens, round(who.seconds(), 1), round(machine, 1), shot.name, before,
                             after, who.log))
    return made


def markdown(made: list[Made], image_dir: str = "img/newcomer") -> str:
    """The table for docs/agile-loop.md."""
    rows = ["| ID | Change | Paper (m:ss) | What the newcomer does | Actions | Clicks | Typed | Words read | Screens "
            "| Person (s) | Machine (s) | Screenshot |",
            "|---:|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for m in made:
        rows.append(f"| {m.id} | {m.suggestion} | {m.paper_time} | {m.how} | {m.actions} | {m.clicks} | {m.typed} | "
                    f"{m.words} | {m.screens} | {m.person_s:.1f} | {m.machine_s:.1f} | "
                    f"[{m.screenshot}]({image_dir}/{m.screenshot}) |")
    rows.append(f"| | **all {len(made)}** | | | {sum(m.actions for m in made)} | {sum(m.clicks for m in made)} | "
                f"{sum(m.typed for m in made)} | {sum(m.words for m in made)} | {sum(m.screens for m in made)} | "
                f"**{sum(m.person_s for m in made):.1f}** | {sum(m.machine_s for m in made):.1f} | |")
    return "\n".join(rows)


def steps_markdown(made: list[Made]) -> str:
    out = ["<details><summary>The newcomer's steps, change by change</summary>", ""]
    for m in made:
        out.append(f"**#{m.id}** ({m.person_s:.0f} s): " + " · ".join(m.log))
        out.append("")
    out.append("</details>")
    return "\n".join(out)
