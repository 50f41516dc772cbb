"""Scenario tests for the teahouse reception rule set (rules/drl/reception/).

Each scenario gives the facts the sensing side would send (an Entrance with its count, the
Customers the age/gender estimator saw, Pepper's position) and checks, through the real engine
on a real JVM, which rules fired and which robot actions came out, in order. Together the
scenarios fire every one of the 32 rules; a rule without a scenario fails the coverage test.
"""

from __future__ import annotations

import json
import re
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from gateway.config import Settings
from gateway.engine import Engine
from gateway.engine.ruleset import read_folder

RULES_DIR = Path(__file__).resolve().parents[2] / "rules" / "drl" / "reception"
RULE_SET = "reception"
TYPE_RULES = {"Infant", "Child", "Teenager", "Adult", "Senior", "Age not estimated"}
# Far above what any scenario needs (one firing per customer + 3 per entrance): a loop would hit it.
FIRE_LIMIT = 200

Fact = dict[str, Any]


# --- facts ---------------------------------------------------------------------------------

def entrance(n: int, id: str = "entrance") -> Fact:
    return {"type": "Entrance", "id": id, "number_of_customers": n}


def customer(cid: str, age: int, gender: str = "female", at: str | None = "entrance") -> Fact:
    fact: Fact = {"type": "Customer", "id": cid, "age": age, "gender": gender, "distance": 1.5}
    if at is not None:
        fact["entrance"] = at
    return fact


def pepper(position: str = "entrance") -> Fact:
    return {"type": "Robot", "id": "pepper", "position": position}


def party(*people: tuple[int, str], at: str = "entrance", prefix: str = "c") -> list[Fact]:
    """An Entrance counting len(people) plus one Customer per (age, gender)."""
    facts = [entrance(len(people), at)]
    facts += [customer(f"{prefix}{i}", age, gender, at) for i, (age, gender) in enumerate(people, 1)]
    return facts


# --- actions -------------------------------------------------------------------------------

def say(text: str) -> Fact:
    return {"module": "say", "params": {"robot": "pepper", "text": text}}


def gesture(name: str) -> Fact:
    return {"module": "gesture", "params": {"robot": "pepper", "name": name}}


def move(location: str) -> Fact:
    return {"module": "move", "params": {"robot": "pepper", "location": location}}


def staff(task: str, at: str = "entrance") -> Fact:
    return {"module": "notify_staff", "params": {"entrance": at, "task": task}}


# --- scenarios: (id, facts, rules fired after the customer types, actions) ----------------

SCENARIOS = [
    ("oversized party",
     party(*[(30 + i, "male") for i in range(9)]) + [pepper()],
     ["Oversized party", "Apologise to an oversized party"],
     [say("Welcome. We are sorry, we can seat at most eight guests together. "
          "May we seat you at separate tables?"),
      gesture("apologise"), staff("help seat a large party")]),
    ("children on their own",
     party((8, "male"), (3, "female")) + [pepper()],
     ["Children on their own", "Talk to children on their own"],
     [say("Hello! Are you here with your family? Please wait here with me."),
      gesture("wave"), staff("look after children at the entrance")]),
    ("family with a baby",
     party((35, "female"), (37, "male"), (1, "female")) + [pepper()],
     ["Family with a baby", "Greet a family with a baby"],
     [say("Welcome! We will bring a baby chair for the little one."), gesture("wave"),
      staff("bring a baby chair"), move("family table")]),
    ("parent and child",
     party((40, "female"), (7, "male")) + [pepper()],
     ["Parent and child", "Greet a parent and child"],
     [say("Welcome. Two seats? We will bring a child seat."), gesture("wave"),
      staff("bring a child seat"), move("table for two")]),
    ("family",
     party((42, "male"), (41, "female"), (9, "female"), (15, "male")) + [pepper()],
     ["Family", "Greet a family"],
     [say("Welcome! A table for the whole family? We will bring child seats."), gesture("wave"),
      staff("bring child seats"), move("family table")]),
    ("senior group",
     party((70, "female"), (72, "male"), (81, "female")) + [pepper()],
     ["Senior group", "Greet a senior group"],
     [say("Welcome. Please watch your step. Would you like blankets for your legs?"),
      gesture("bow deeply"), staff("bring blankets"), move("table near the entrance")]),
    ("senior couple is a senior group",
     party((70, "female"), (72, "male")) + [pepper()],
     ["Senior group", "Greet a senior group"],
     [say("Welcome. Please watch your step. Would you like blankets for your legs?"),
      gesture("bow deeply"), staff("bring blankets"), move("table near the entrance")]),
    ("couple",
     party((30, "male"), (28, "female")) + [pepper()],
     ["Couple", "Greet a couple"],
     [say("Welcome. Two seats? We have a table by the window for you."), gesture("bow"),
      move("window table")]),
    ("single senior",
     party((80, "male")) + [pepper()],
     ["Single senior", "Greet a single senior"],
     [say("Welcome. Please take your time. One seat?"), gesture("bow deeply"),
      move("table near the entrance")]),
    ("pair: the papers' greeting",
     party((25, "female"), (27, "female")) + [pepper()],
     ["Pair", "Greet a pair"],
     [say("Welcome. Two seats?"), gesture("bow"), move("table for two")]),
    ("teenage boy and girl are a pair, not a couple",
     party((16, "male"), (17, "female")) + [pepper()],
     ["Pair", "Greet a pair"],
     [say("Welcome. Two seats?"), gesture("bow"), move("table for two")]),
    ("single guest",
     party((17, "male")) + [pepper()],
     ["Single guest", "Greet a single guest"],
     [say("Welcome. One seat?"), gesture("bow"), move("counter")]),
    ("three customers",
     party((30, "male"), (31, "male"), (-1, "unknown")) + [pepper()],
     ["Small group", "Greet three customers"],
     [say("Welcome. Three seats?"), gesture("bow"), move("table for four")]),
    ("four customers",
     party((30, "male"), (16, "female"), (66, "female"), (45, "male")) + [pepper()],
     ["Small group", "Greet four customers"],
     [say("Welcome. Four seats?"), gesture("bow"), move("table for four")]),
    ("large group",
     party(*[(20 + i, "female") for i in range(6)]) + [pepper()],
     ["Large group", "Greet a large group"],
     [say("Welcome. Please wait a moment while we prepare the large table."), gesture("bow"),
      staff("prepare the large table"), move("large table")]),
    ("Pepper is called from the kitchen first",
     party((25, "female"), (27, "female")) + [pepper("kitchen")],
     ["Pair", "Call Pepper to the entrance", "Greet a pair"],
     [move("entrance"), say("Welcome. Two seats?"), gesture("bow"), move("table for two")]),
    ("without Pepper the group is formed and nobody is greeted",
     party((30, "male"), (28, "female")),
     ["Couple"],
     []),
]

# Customer type rules: one customer at no entrance, so only the type rule fires.
TYPE_SCENARIOS = [
    ("Infant", 2, "infant"),
    ("Child", 8, "child"),
    ("Teenager", 16, "teenager"),
    ("Adult", 40, "adult"),
    ("Senior", 70, "senior"),
    ("Age not estimated", -1, "adult"),
]

# The age ranges' edges: age -> category.
AGE_EDGES = {0: "infant", 3: "infant", 4: "child", 12: "child", 13: "teenager", 19: "teenager",
             20: "adult", 64: "adult", 65: "senior", 110: "senior", -1: "adult"}


# --- fixtures and helpers ------------------------------------------------------------------

def rule_set_files() -> dict[str, str]:
    """The folder as the engine's loader reads it (rule files and examples.json)."""
    return read_folder(RULES_DIR)


@pytest.fixture(scope="module")
def engine(tmp_path_factory: pytest.TempPathFactory) -> Engine:
    """One engine (and one compile of the rule set) for the whole module."""
    eng = Engine(Settings(data_dir=str(tmp_path_factory.mktemp("reception-data"))))
    eng.deploy(RULE_SET, rule_set_files(), author="tests", comment="reception scenarios")
    return eng


def fire(engine: Engine, facts: list[Fact]) -> tuple[list[str], list[Fact], list[Fact]]:
    """Fire the rule set: (rule names in firing order, actions without their 'rule', facts out)."""
    result = engine.fire(RULE_SET, facts, fire_limit=FIRE_LIMIT)
    names = [f["rule"] for f in result.fired]
    actions = [{"module": a["module"], "params": a["params"]} for a in result.actions]
    assert len(names) <= sum(f["type"] == "Customer" for f in facts) + 3 * max(
        1, sum(f["type"] == "Entrance" for f in facts)), f"too many firings: {names}"
    return names, actions, result.facts


RULE_FOR_CATEGORY = {"infant": "Infant", "child": "Child", "teenager": "Teenager",
                     "adult": "Adult", "senior": "Senior"}


def category_of(age: int) -> str:
    """The category the age ranges in reception.dslr give (ages below 0: not estimated)."""
    if age < 0:
        return "adult"
    if age <= 3:
        return "infant"
    if age <= 12:
        return "child"
    if age <= 19:
        return "teenager"
    return "adult" if age <= 64 else "senior"


def expected_types(facts: list[Fact]) -> Counter:
    """The type rule each customer should trigger, by its age."""
    return Counter("Age not estimated" if f["age"] < 0 else RULE_FOR_CATEGORY[category_of(f["age"])]
                   for f in facts if f["type"] == "Customer")


# --- tests ---------------------------------------------------------------------------------

def test_the_rule_set_has_32_rules_in_three_kinds() -> None:
    text = rule_set_files()["reception.dslr"]
    names = re.findall(r'^rule "([^"]+)"', text, re.M)
    assert len(names) == 32 and len(set(names)) == 32
    # The file's three sections: customer type, group, speech and motion.
    sections = re.split(r"^// \d\. ", text, flags=re.M)[1:]
    assert [len(re.findall(r'^rule "', sec, re.M)) for sec in sections] == [6, 12, 14]
    assert set(re.findall(r'^rule "([^"]+)"', sections[0], re.M)) == TYPE_RULES


def test_every_rule_has_a_scenario() -> None:
    names = set(re.findall(r'^rule "([^"]+)"', rule_set_files()["reception.dslr"], re.M))
    covered = {name for _, _, fired, _ in SCENARIOS for name in fired}
    covered |= {name for name, _, _ in TYPE_SCENARIOS}
    assert names - covered == set()


def test_the_rule_set_compiles_cleanly(engine: Engine) -> None:
    assert engine.validate(RULE_SET, rule_set_files()) == []


def test_the_dsl_expands_every_line(engine: Engine) -> None:
    """No owner-language line is left untranslated: the expanded text is plain DRL."""
    drl = engine.expand(RULE_SET, rule_set_files())["reception.dslr"]
    for phrase in ("There is", "Pepper says", "The party", "Everyone", "Someone", "- of", "- aged"):
        assert phrase not in drl, phrase


@pytest.mark.parametrize("rule, age, category", TYPE_SCENARIOS, ids=[s[0] for s in TYPE_SCENARIOS])
def test_customer_type(engine: Engine, rule: str, age: int, category: str) -> None:
    names, actions, facts = fire(engine, [customer("c1", age, at=None)])
    assert names == [rule]
    assert actions == []
    assert [f["category"] for f in facts if f["type"] == "Customer"] == [category]


def test_age_range_edges(engine: Engine) -> None:
    facts = [customer(f"age{age}", age, at=None) for age in AGE_EDGES]
    _, _, out = fire(engine, facts)
    got = {f["id"]: f["category"] for f in out if f["type"] == "Customer"}
    assert got == {f"age{age}": category for age, category in AGE_EDGES.items()}
    assert all(category_of(age) == category for age, category in AGE_EDGES.items())


@pytest.mark.parametrize("name, facts, fired, actions", SCENARIOS, ids=[s[0] for s in SCENARIOS])
def test_scenario(engine: Engine, name: str, facts: list[Fact], fired: list[str],
                  actions: list[Fact]) -> None:
    names, got_actions, out = fire(engine, facts)
    assert Counter(n for n in names if n in TYPE_RULES) == expected_types(facts)
    assert [n for n in names if n not in TYPE_RULES] == fired
    assert got_actions == actions
    groups = [f for f in out if f["type"] == "Group"]
    assert len(groups) == 1
    assert groups[0]["greeted"] is any(a["module"] == "say" for a in actions)


def test_two_entrances_one_pepper_terminates(engine: Engine) -> None:
    """Pepper greets one party, then is called to the other: each party is greeted once."""
    facts = (party((30, "male"), (28, "female"), at="front", prefix="f")
             + party((80, "male"), at="side", prefix="s") + [pepper("kitchen")])
    names, actions, out = fire(engine, facts)
    others = [n for n in names if n not in TYPE_RULES]
    assert Counter(others) == Counter({"Couple": 1, "Single senior": 1,
                                       "Call Pepper to the entrance": 2,
                                       "Greet a couple": 1, "Greet a single senior": 1})
    # Each call is directly followed by that entrance's greeting.
    for i, n in enumerate(others):
        if n == "Call Pepper to the entrance":
            assert others[i + 1].startswith("Greet")
    assert sorted(a["params"]["text"] for a in actions if a["module"] == "say") == [
        "Welcome. Please take your time. One seat?",
        "Welcome. Two seats? We have a table by the window for you."]
    assert all(f["greeted"] for f in out if f["type"] == "Group")


def test_examples_file_is_well_formed() -> None:
    """examples.json (the workbench's ready examples): a list of uniquely named fact lists."""
    examples = json.loads((RULES_DIR / "examples.json").read_text(encoding="utf-8"))
    assert examples and all({"name", "facts"} <= set(e) for e in examples)
    assert len({e["name"] for e in examples}) == len(examples)


@pytest.mark.parametrize("example", json.loads((RULES_DIR / "examples.json").read_text(encoding="utf-8")),
                         ids=lambda e: e["name"])
def test_example_fires(engine: Engine, example: dict[str, Any]) -> None:
    names, actions, _ = fire(engine, example["facts"])
    assert names, "no rule fired"
    assert any(a["module"] == "say" for a in actions)
