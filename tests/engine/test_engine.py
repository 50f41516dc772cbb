"""The engine core against a real JVM running Drools."""

from __future__ import annotations

import json
import threading

import pytest

from gateway.config import Settings
from gateway.engine import (
    CompileFailed,
    Engine,
    FactError,
    InvalidRuleSet,
    RuleRuntimeError,
    RuleSetNotFound,
    RunawayRules,
    VersionConflict,
)

from engine_samples import RULES, TYPES

FIVE_FACTS = [
    {"type": "Customer", "id": "c1", "age": 30, "gender": "female", "distance": 1.5},
    {"type": "Customer", "id": "c2", "age": 12, "gender": "male", "distance": 1.6},
    {"type": "Group", "id": "g1", "size": 2},
]


def test_fire_returns_actions_fired_rules_and_facts(engine, simple_files):
    engine.deploy("t", simple_files, author="alice", comment="first")
    result = engine.fire("t", FIVE_FACTS)
    assert result.version == 1
    modules = [(a["module"], a["params"]) for a in result.actions]
    assert ("say", {"robot": "pepper", "text": "Hello c1"}) in modules
    group_actions = [a for a in result.actions if a["rule"] == "group of two"]
    assert [a["module"] for a in group_actions] == ["say", "move", "gesture"]
    assert group_actions[0]["params"]["text"] == "Welcome. Two seats?"
    fired = {f["rule"]: f["facts"] for f in result.fired}
    assert fired["greet adult"] == [{"type": "Customer", "id": "c1", "age": 30, "gender": "female", "distance": 1.5}]
    assert len(result.facts) == 3
    assert result.to_dict()["actions"] == result.actions


@pytest.mark.parametrize(
    "facts, fragment, field",
    [
        ([{"type": "Customr", "id": "x"}], "unknown type 'Customr'", "type"),
        ([{"type": "Customer", "id": "c1", "agee": 3}], "unknown field 'agee'", "agee"),
        ([{"type": "Customer", "id": "c1", "age": "thirty"}], "expected int, got string", "age"),
        ([{"type": "Customer", "id": "c1", "age": None}], "null is not allowed", "age"),
        ([{"type": "Customer", "id": "c1", "age": 1.5}], "expected int", "age"),
        ([{"type": "Customer", "id": "c1", "age": 2**40}], "out of range", "age"),
        ([{"type": "Customer", "id": "c1", "gender": 7}], "expected String", "gender"),
        ([{"id": "c1"}], "needs a \"type\"", "type"),
        (["not an object"], "must be a JSON object", None),
    ],
)
def test_bad_facts_are_refused_naming_fact_and_field(engine, simple_files, facts, fragment, field):
    engine.deploy("t", simple_files)
    with pytest.raises(FactError) as err:
        engine.fire("t", [FIVE_FACTS[0], *facts])
    assert fragment in str(err.value)
    problem = err.value.errors[0]
    assert problem["index"] == 1
    assert problem["field"] == field


def test_facts_must_be_a_list_and_json(engine, simple_files):
    engine.deploy("t", simple_files)
    with pytest.raises(FactError, match="must be a list"):
        engine.fire("t", {"type": "Customer"})  # type: ignore[arg-type]
    with pytest.raises(FactError, match="NaN"):
        engine.fire("t", [{"type": "Customer", "id": "c", "distance": float("nan")}])


def test_deeply_nested_and_oversized_requests(engine, simple_files):
    engine.deploy("t", simple_files)
    nested: object = 1
    for _ in range(200):
        nested = [nested]
    with pytest.raises(FactError, match="nesting deeper"):
        engine.fire("t", [{"type": "Customer", "id": "c", "gender": nested}])
    big = [{"type": "Customer", "id": f"c{i}", "age": 20, "gender": "x" * 100} for i in range(100_001)]
    with pytest.raises(FactError, match="too many facts"):
        engine.fire("t", big)
    assert engine.fire("t", FIVE_FACTS).version == 1  # still serving


def test_all_errors_reported_not_only_the_first(engine, simple_files):
    engine.deploy("t", simple_files)
    with pytest.raises(FactError) as err:
        engine.fire("t", [{"type": "Nope"}, FIVE_FACTS[0], {"type": "Customer", "age": "x"}])
    assert [e["index"] for e in err.value.errors] == [0, 2]


def _errors(engine, files):
    with pytest.raises(CompileFailed) as failed:
        engine.deploy("t", files)
    return failed.value.errors


def test_drl_syntax_error_has_line_and_column(engine):
    rules = RULES.replace("Customer(age >= 18)", "Customer(age >= )")
    errors = _errors(engine, {"types.drl": TYPES, "rules.drl": rules})
    line_no = rules.split("\n").index("    $c: Customer(age >= )") + 1
    assert (errors[0].file, errors[0].line) == ("rules.drl", line_no)
    assert errors[0].column > 0


def test_unknown_type_and_field_are_located(engine):
    errors = _errors(engine, {"types.drl": TYPES, "rules.drl": RULES.replace("$c: Customer(age", "$c: Customr(age")})
    assert errors[0].file == "rules.drl" and "Customr" in errors[0].message
    assert errors[0].line == 5 and errors[0].column == 9
    errors = _errors(engine, {"types.drl": TYPES, "rules.drl": RULES.replace("age >= 18", "agee >= 18")})
    assert errors[0].file == "rules.drl" and errors[0].line == 5 and "agee" in errors[0].message


def test_java_error_in_then_part_is_located(engine):
    rules = RULES.replace('actions.gesture("pepper", "bow");', 'actions.fly("pepper");')
    errors = _errors(engine, {"types.drl": TYPES, "rules.drl": rules})
    line_no = next(i for i, line in enumerate(rules.split("\n"), 1) if "actions.fly" in line)
    assert errors[0].file == "rules.drl" and errors[0].line == line_no
    assert "fly" in errors[0].message


DSL = """[condition][]There is a customer aged at least {age}=$c: Customer(age >= {age})
[condition][]- who is {gender}=gender == "{gender}"
[consequence][]Pepper says "{text}"=actions.say("pepper", "{text}");
"""

DSLR = """package org.printeps.test;
expander teahouse.dsl

rule "greet women"
when
    There is a customer aged at least 18
    - who is female
then
    Pepper says "Welcome, madam"
end
"""


def test_dsl_rules_compile_expand_and_fire(engine):
    files = {"types.drl": TYPES, "teahouse.dsl": DSL, "greet.dslr": DSLR}
    engine.deploy("dsl", files)
    result = engine.fire("dsl", [FIVE_FACTS[0], FIVE_FACTS[1]])
    assert [a["params"]["text"] for a in result.actions] == ["Welcome, madam"]
    expanded = engine.expand("dsl", files)["greet.dslr"]
    assert 'Customer(age >= 18, gender == "female")' in expanded.replace("\n", " ") or "gender == \"female\"" in expanded


def test_dsl_sentence_without_mapping_is_marked_where_it_stands(engine):
    files = {"types.drl": TYPES, "teahouse.dsl": DSL, "greet.dslr": DSLR.replace("aged at least 18", "older than 18")}
    errors = _errors(engine, files)
    assert errors[0].file == "greet.dslr" and errors[0].line == 6 and errors[0].column == 5
    assert "There is a customer older than 18" in errors[0].message


def test_broken_dsl_mapping_line(engine):
    files = {"types.drl": TYPES, "teahouse.dsl": DSL + "[condition][broken mapping\n", "greet.dslr": DSLR}
    errors = _errors(engine, files)
    assert errors[0].file == "teahouse.dsl" and errors[0].line == 4


def test_missing_expander(engine):
    errors = _errors(engine, {"types.drl": TYPES, "greet.dslr": DSLR})
    assert errors[0].file == "greet.dslr" and "teahouse.dsl" in errors[0].message and errors[0].line == 2


@pytest.mark.parametrize(
    "files, fragment",
    [
        ({}, "empty rule set"),
        ({"a.drl": "   "}, "empty rule set"),
        ({"only.dsl": DSL}, "no .drl or .dslr"),
        ({"../evil.drl": RULES}, "invalid file name"),
        ({"a.txt": "x"}, "unsupported file"),
        ({"a.drl": "rule \x00\x01 binary"}, "binary"),
        ({"a.drl": "x" * 1_000_001}, "too large"),
    ],
)
def test_unusable_rule_sets_are_refused(engine, files, fragment):
    errors = _errors(engine, files)
    assert fragment in errors[0].message


@pytest.mark.parametrize("name", ["../x", "a b", "", "a/b", ".hidden", "x" * 80])
def test_bad_rule_set_names(engine, simple_files, name):
    with pytest.raises(InvalidRuleSet):
        engine.deploy(name, simple_files)


def test_failed_deploy_changes_nothing(engine, simple_files):
    engine.deploy("t", simple_files)
    with pytest.raises(CompileFailed):
        engine.deploy("t", {"types.drl": TYPES, "rules.drl": "rule broken when then"})
    assert engine.current("t").info.version == 1
    assert [v.version for v in engine.versions("t")] == [1]
    assert engine.fire("t", FIVE_FACTS).version == 1


def test_versions_rollback_delete_and_persistence(tmp_path, simple_files, store):
    from gateway.store.catalog import MongoCatalog

    settings = Settings(data_dir=str(tmp_path / "data"))
    engine = Engine(settings, MongoCatalog(store.db, "first-process"))
    v1 = engine.deploy("t", simple_files, author="alice", comment="first")
    changed = {**simple_files, "rules.drl": RULES.replace("Welcome. Two seats?", "Welcome! A table for two?")}
    v2 = engine.deploy("t", changed, author="bob", comment="friendlier", base_version=1)
    assert v2.version == 2 and v2.hash != v1.hash
    assert "A table for two" in json.dumps(engine.fire("t", FIVE_FACTS).actions)
    with pytest.raises(VersionConflict) as conflict:
        engine.deploy("t", simple_files, base_version=1)
    assert conflict.value.current == 2
    engine.rollback("t", 1, author="alice")
    assert engine.fire("t", FIVE_FACTS).version == 1

    restarted = Engine(settings, MongoCatalog(store.db, "restarted"))  # a new process sees the same
    assert restarted.current("t").info.version == 1
    assert [(v.version, v.author, v.comment) for v in restarted.versions("t")] == [(1, "alice", "first"), (2, "bob", "friendlier")]
    assert restarted.version("t", 2).files == changed
    assert restarted.fire("t", FIVE_FACTS).version == 1
    restarted.delete("t")
    with pytest.raises(RuleSetNotFound):
        restarted.fire("t", FIVE_FACTS)
    assert restarted.list_rulesets() == []
    v3 = restarted.deploy("t", simple_files)
    assert v3.version == 3  # numbering continues, history kept
    assert [e["event"] for e in restarted.history("t")] == ["deploy", "deploy", "rollback", "delete", "deploy"]


def test_hot_swap_while_firing(engine, simple_files):
    engine.deploy("t", simple_files)
    texts = {1: "Welcome. Two seats?"}
    stop = threading.Event()
    answers: list[tuple[int, str]] = []
    failures: list[BaseException] = []

    def client() -> None:
        while not stop.is_set():
            try:
                result = engine.fire("t", FIVE_FACTS)
                text = next(a["params"]["text"] for a in result.actions if a["rule"] == "group of two")
                answers.append((result.version, text))
            except BaseException as exc:  # noqa: BLE001 - any failure fails the test
                failures.append(exc)

    threads = [threading.Thread(target=client) for _ in range(3)]
    for t in threads:
        t.start()
    try:
        for i in range(2, 7):
            text = f"Welcome number {i}. Two seats?"
            info = engine.deploy("t", {**simple_files, "rules.drl": RULES.replace("Welcome. Two seats?", text)})
            texts[info.version] = text
        engine.rollback("t", 3)
    finally:
        stop.set()
        for t in threads:
            t.join(timeout=30)
    assert not failures
    assert answers
    assert all(texts[version] == text for version, text in answers)  # each answer matches its version


def test_runaway_rules_are_stopped(engine, simple_files):
    loop = RULES + """
rule "forever"
when
    $c: Customer(age > 0)
then
    modify($c) { setAge($c.getAge() + 1) };
end
"""
    engine.deploy("loop", {"types.drl": TYPES, "rules.drl": loop})
    with pytest.raises(RunawayRules) as err:
        engine.fire("loop", FIVE_FACTS, fire_limit=500)
    counts = err.value.counts
    assert sum(counts.values()) >= 500 and max(counts, key=counts.get) == "forever"
    assert "forever" in str(err.value)


def test_exception_in_then_part_is_reported(engine):
    boom = RULES.replace('actions.say("pepper", "Hello " + $c.getId());', 'Integer.parseInt($c.getId());')
    engine.deploy("boom", {"types.drl": TYPES, "rules.drl": boom})
    with pytest.raises(RuleRuntimeError) as err:
        engine.fire("boom", FIVE_FACTS)
    assert err.value.rule == "greet adult" and "NumberFormatException" in str(err.value)


def test_generic_call_action(engine):
    rules = RULES.replace(
        'actions.gesture("pepper", "bow");',
        'java.util.Map p = new java.util.HashMap(); p.put("table", "t1"); p.put("seats", 2); actions.call("reserve", p);',
    )
    engine.deploy("t", {"types.drl": TYPES, "rules.drl": rules})
    result = engine.fire("t", FIVE_FACTS)
    assert {"module": "reserve", "params": {"table": "t1", "seats": 2}, "rule": "group of two"} in result.actions


def test_try_undeployed_files(engine, simple_files):
    result = engine.fire_files(simple_files, FIVE_FACTS)
    assert result.ruleset == "(draft)" and result.actions
    assert engine.list_rulesets() == []


def test_declared_types(engine, simple_files):
    engine.deploy("t", simple_files)
    assert engine.declared_types("t")["Customer"] == {"id": "String", "age": "int", "gender": "String", "distance": "double"}
    assert engine.type_names("t")["Group"] == "org.printeps.test.Group"


EVENTS = TYPES + """
declare CustomerEntered
    @role(event)
    @timestamp(ts)
    id: String
    ts: long
end

rule "two entries within 5 seconds"
when
    $a: CustomerEntered()
    $b: CustomerEntered(this != $a, this after[0s, 5s] $a)
then
    actions.say("pepper", "Welcome, " + $a.getId() + " and " + $b.getId());
end
"""


def test_stateful_session_with_events_and_facts(engine):
    engine.deploy("ev", {"rules.drl": EVENTS, "more.drl": RULES})
    session = engine.open_session("ev")
    try:
        session.insert_event({"type": "CustomerEntered", "id": "c1", "ts": 1_000}, 1_000)
        assert session.fire().actions == []
        session.insert_event({"type": "CustomerEntered", "id": "c2", "ts": 3_000}, 3_000)
        assert [a["params"]["text"] for a in session.fire().actions] == ["Welcome, c1 and c2"]
        session.insert_event({"type": "CustomerEntered", "id": "c3", "ts": 20_000}, 20_000)
        assert session.fire().actions == []  # too late for c2: outside the 5 s window
        assert session.clock_ms == 20_000

        session.insert([{"type": "Customer", "id": "k", "age": 10}])
        assert session.fire().actions == []
        session.update({"type": "Customer", "id": "k", "age": 19})
        assert [a["params"]["text"] for a in session.fire().actions] == ["Hello k"]
        with pytest.raises(FactError, match="already in the session"):
            session.insert([{"type": "Customer", "id": "k", "age": 40}])
        session.retract("k")
        with pytest.raises(FactError, match="no fact with id"):
            session.retract("k")
    finally:
        engine.close_session(session.id)


def test_rules_dir_only_seeds_what_the_catalog_never_had(tmp_path, simple_files):
    rules = tmp_path / "rules"
    (rules / "good").mkdir(parents=True)
    for name, text in simple_files.items():
        (rules / "good" / name).write_text(text)
    (rules / "bad").mkdir()
    (rules / "bad" / "rules.drl").write_text("rule broken when then")
    engine = Engine(Settings(data_dir=str(tmp_path / "data"), engine={"rules_dir": str(rules)}))
    report = engine.seed(rules)
    assert report["good"] == "seeded v1" and report["bad"].startswith("failed")
    (rules / "good" / "rules.drl").write_text(RULES.replace("Welcome. Two seats?", "changed on disk"))
    assert engine.seed(rules)["good"] == "kept v1"  # files never overwrite what the store has
    assert engine.fire("good", FIVE_FACTS).version == 1
    engine.delete("good")
    assert engine.seed(rules)["good"] == "kept (deleted)"


def test_listener_sees_deploys_and_fires(engine, simple_files):
    seen: list[str] = []
    deaf: list[str] = []  # a listener to the life cycle only (as the session manager): decisions pass it by
    engine.add_listener(lambda kind, payload: deaf.append(kind), fires=False)
    engine.add_listener(lambda kind, payload: seen.append(kind))
    engine.add_listener(lambda kind, payload: 1 / 0)  # a broken listener does not break firing
    engine.deploy("t", simple_files)
    engine.fire("t", FIVE_FACTS)
    assert seen == ["deploy", "fire"] and deaf == ["deploy"]


def test_the_process_warm_up_fires_the_live_sets_and_records_no_decision(engine, simple_files):
    engine.deploy("warmed", simple_files)
    seen: list[str] = []
    engine.add_listener(lambda kind, payload: seen.append(kind))
    before = engine.recent_requests("warmed")
    assert engine.warm_up(rounds=1, fires=3, background=False) is None
    assert "fire" not in seen  # warm-up is no decision
    assert len(engine.recent_requests("warmed")) == min(len(before) + 3, Engine.RECENT_REQUESTS)  # it did fire


def test_dslr_error_lines_account_for_continuation_lines(engine):
    # Two "- " continuation lines above the error are folded away by the expander: the reported
    # line must still be the .dslr line, not the expanded one.
    extra = """
rule "duplicate"
when
    There is a customer aged at least 18
    - who is female
then
    Pepper says "again"
end

rule "greet women"
when
    There is a customer aged at least 30
then
    Pepper says "twice"
end
"""
    dslr = DSLR + extra
    errors = _errors(engine, {"types.drl": TYPES, "teahouse.dsl": DSL, "greet.dslr": dslr})
    lines = dslr.split("\n")
    second = [i for i, line in enumerate(lines, 1) if line.startswith('rule "greet women"')][1]
    assert errors[0].file == "greet.dslr" and "Duplicate rule name" in errors[0].message
    assert errors[0].line == second


def test_then_part_using_an_unbound_variable(engine):
    dsl = DSL + "[consequence][]The customer is greeted=actions.say(\"pepper\", \"Hi \" + $c.getId());\n"
    dslr = """package org.printeps.test;
expander teahouse.dsl

rule "no customer"
when
    >eval(true)
then
    The customer is greeted
end
"""
    errors = _errors(engine, {"types.drl": TYPES, "teahouse.dsl": dsl, "greet.dslr": dslr})
    assert (errors[0].file, errors[0].line) == ("greet.dslr", 8)
    assert "$c" in errors[0].message and "does not bind" in errors[0].message


def test_queries_and_globals_in_a_stateful_session(engine):
    rules = TYPES + """
global java.lang.Integer minimumAge;
global java.util.List seen;

query "adults older than" (int limit)
    $c: Customer(age > limit)
end

rule "remember adults"
when
    $c: Customer(age >= minimumAge)
then
    seen.add($c.getId());
end
"""
    engine.deploy("q", {"rules.drl": rules})
    session = engine.open_session("q")
    try:
        session.set_global("minimumAge", 18)
        session.set_global("seen", [])
        session.insert([FIVE_FACTS[0], FIVE_FACTS[1]])
        session.fire()
        assert session.get_global("seen") == ["c1"]
        answer = session.query("adults older than", [20])
        assert answer["identifiers"] == ["$c", "limit"] or "$c" in answer["identifiers"]
        assert [row["$c"]["id"] for row in answer["rows"]] == ["c1"]
        with pytest.raises(FactError, match="declares no global"):
            session.set_global("nope", 1)
        with pytest.raises(FactError, match="expected Integer"):
            session.set_global("minimumAge", "eighteen")
        with pytest.raises(FactError, match="belongs to the gateway"):
            session.set_global("actions", None)
        with pytest.raises(FactError, match="query 'missing' failed"):
            session.query("missing")
    finally:
        session.close()
    assert engine.sessions() == []
