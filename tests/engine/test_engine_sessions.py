"""Sessions in the core (no HTTP): kmodule.xml declarations and their errors, the deploy policy
(a session that cannot follow stays on its version and says why; a stream-bound session follows
like any other), refraction across a move, and a stream session resolving KIE handles."""

from __future__ import annotations

import pytest

from gateway.engine import kmodule
from gateway.engine.errors import CompileFailed
from gateway.engine.session import CommandFailed
from gateway.engine.sessions import rule_fingerprints

TYPES = """package org.printeps.sess;
import org.printeps.gateway.Actions;
global Actions actions;
declare Guest
    id : String
    party : int
end
"""
RULES = """package org.printeps.sess;
import org.printeps.gateway.Actions;
global Actions actions;
rule "Seat"
when
    $g : Guest( party > 0 )
then
    actions.say("pepper", "SEAT " + $g.getId());
end
rule "Count"
when
    Number( $n : intValue > 0 ) from accumulate( Guest(), count(1) )
then
    actions.call("count", "n", $n);
end
"""


def files(word: str = "Seat", types: str = TYPES) -> dict[str, str]:
    return {"types.drl": types, "rules.drl": RULES.replace("SEAT", word)}


def test_kmodule_parsing_and_positions():
    assert kmodule.declarations({}) is kmodule.KIE_DEFAULTS
    parsed = kmodule.parse("""<kmodule xmlns="http://www.drools.org/xsd/kmodule">
  <kbase name="k" packages="a.b" eventProcessingMode="stream">
    <ksession name="s1" default="true"/>
    <ksession name="s2" type="stateless" default="true" clockType="pseudo"/>
  </kbase>
</kmodule>""")
    assert [(s.name, s.stateful, s.clock, s.default) for s in parsed.sessions] == [
        ("s1", True, "realtime", True), ("s2", False, "pseudo", True)]
    for text, line, column, message in (
        ("<kmodule><kbase>", 1, 17, "not well-formed XML"),
        ("<module/>", 1, 1, "the root element must be <kmodule>"),
        ('<kmodule>\n<kbase>\n<ksession/>\n</kbase></kmodule>', 3, 1, "a <ksession> needs a name"),
        ('<kmodule>\n<kbase>\n <ksession name="a" clockType="wall"/>\n</kbase></kmodule>', 3, 2, "clockType must be"),
        ('<kmodule><kbase><ksession name="a"/><ksession name="a"/></kbase></kmodule>', 1, 37, "declared twice"),
        ('<kmodule><kbase><ksession name="a" colour="red"/></kbase></kmodule>', 1, 17, "unknown attribute(s) colour"),
        ('<!DOCTYPE x [<!ENTITY a "b">]><kmodule/>', 1, 1, "DTDs and entities are not allowed"),
    ):
        with pytest.raises(kmodule.KmoduleError) as caught:
            kmodule.parse(text)
        error = caught.value.errors[0]
        assert (error.file, error.line, error.column) == ("kmodule.xml", line, column), (text, error)
        assert message in error.message


def test_kmodule_errors_come_with_compile_errors(engine):
    broken = {**files(), "kmodule.xml": "<kmodule><kbase><ksession name='x' default='maybe'/></kbase></kmodule>"}
    errors = engine.validate("kx", broken)
    assert [(e.file, e.message) for e in errors] == [("kmodule.xml", "ksession 'x': default must be true or false, not 'maybe'")]
    with pytest.raises(CompileFailed):
        engine.deploy("kx", broken, force=True)


def test_a_session_that_cannot_follow_stays_and_says_why(engine):
    engine.deploy("stay", files(), force=True)
    session = engine.session_manager.open("stay", kind="rest")
    session.execute([{"op": "insert", "facts": [{"type": "Guest", "id": "g", "party": 2}]}, {"op": "fire", "max": -1}])
    renamed = TYPES.replace("party : int", "size : int")
    engine.deploy("stay", {"types.drl": renamed, "rules.drl": RULES.replace("party > 0", "size > 0")}, force=True)
    assert session.version == 1
    assert "does not fit the new version" in session.pinned_reason and "unknown field 'party'" in session.pinned_reason
    answer = session.execute([{"op": "get_objects"}])  # still answering, on version 1, with its facts
    assert answer.version == 1 and answer.results[0]["value"][0]["party"] == 2
    session.close()


def test_stream_bound_sessions_follow_deploys(engine):
    engine.deploy("streamed", files("Seat"), force=True)
    session = engine.open_session("streamed")  # as the stream engine's stateful binding does
    first = session.push([{"type": "Guest", "id": "g1", "party": 2}], 1_000)
    assert [a["params"]["text"] for a in first.actions if a["module"] == "say"] == ["Seat g1"]
    engine.deploy("streamed", files("Welcome"), force=True)
    assert session.version == 2
    second = session.push([{"type": "Guest", "id": "g2", "party": 3}], 2_000)
    # "Seat" changed: it sees the guest who came across, and the new one; "Count" (unchanged) fires for the new count only
    assert sorted(a["params"]["text"] for a in second.actions if a["module"] == "say") == ["Welcome g1", "Welcome g2"]
    assert [a["params"]["n"] for a in second.actions if a["module"] == "count"] == [2]
    assert session.clock_ms == 2_000
    pinned = engine.open_session("streamed", on_deploy="pin")
    engine.deploy("streamed", files("Hi"), force=True)
    assert session.version == 3 and pinned.version == 2
    for s in (session, pinned):
        engine.close_session(s.id)


def test_pending_matches_survive_a_move(engine):
    engine.deploy("pending", files("Seat"), force=True)
    session = engine.session_manager.open("pending", kind="rest")
    session.execute([{"op": "insert", "facts": [{"type": "Guest", "id": "early", "party": 1}]}, {"op": "fire", "max": -1}])
    session.execute([{"op": "insert", "facts": [{"type": "Guest", "id": "late", "party": 1}]}])  # not fired yet
    engine.deploy("pending", {**files("Seat"), "extra.drl": "package org.printeps.sess;\n"}, force=True)  # rules unchanged
    assert session.version == 2
    answer = session.execute([{"op": "fire", "max": -1}])
    says = [a["params"]["text"] for a in answer.actions() if a["module"] == "say"]
    assert says == ["Seat late"]  # the early guest was seated before the move: not again
    with pytest.raises(CommandFailed) as caught:
        session.execute([{"op": "delete", "handle": "0:999:1:1:1:DEFAULT:NON_TRAIT:x"}])
    assert caught.value.index == 0 and caught.value.kind == "handle"
    session.close()


TABLES = """package org.printeps.sess;
import org.printeps.gateway.Actions;
global Actions actions;
declare Table
    id : String
    state : String
    note : String
end
rule "Free" salience 1
when
    $t : Table( state == "free" )
then
    actions.say("pepper", "Free " + $t.getId());
end
rule "Clean"
when
    $t : Table( state == "free" )
then
    actions.say("pepper", "Clean " + $t.getId());
end
"""


@pytest.mark.parametrize("changed, again", [("note", []), ("state", ["Free t"])])
def test_after_a_move_a_fired_match_fires_again_only_if_a_modify_reaches_it(engine, changed, again):
    """A match that fired before a move (rule unchanged) stays fired through a modify, after the
    move, of a property its rule does not listen to (property reactivity), as in a session that
    never moved; a modify of one it listens to fires it again, in both."""
    engine.deploy("tables", {"tables.drl": TABLES}, force=True)
    said = {}
    for on_deploy in ("pin", "follow"):
        session = engine.session_manager.open("tables", kind="rest", on_deploy=on_deploy)
        handle = session.execute([{"op": "insert", "facts": [{"type": "Table", "id": "t", "state": "free", "note": ""}]},
                                  {"op": "fire", "max": 1}]).results[0]["handles"][0]  # "Free t" fired, "Clean t" waits
        said[on_deploy] = session
        said[on_deploy, "handle"] = handle
    engine.deploy("tables", {"tables.drl": TABLES, "extra.drl": "package org.printeps.sess;\n"}, force=True)  # rules unchanged
    assert said["follow"].version > said["pin"].version
    for on_deploy in ("pin", "follow"):
        session = said[on_deploy]
        value = "free" if changed == "state" else "by the window"
        answer = session.execute([{"op": "modify", "handle": said[on_deploy, "handle"], "set": [[changed, value]]},
                                  {"op": "fire", "max": -1}])
        said[on_deploy] = [a["params"]["text"] for a in answer.actions() if a["module"] == "say"]
        session.close()
    assert said["pin"] == again + ["Clean t"]
    assert said["follow"] == said["pin"]


ONE_LINE = """package org.printeps.sess;
import org.printeps.gateway.Actions;
global Actions actions;
rule "Greet" when $g : Guest() then actions.say("pepper", "Greet " + $g.getId()); end
rule "Offer" when $g : Guest() then actions.say("pepper", "%s " + $g.getId()); end
"""


def test_a_move_tells_unchanged_one_line_rules_from_changed_ones(engine):
    """Rules written on one line each: after a deploy that changes only "Offer", a following session
    fires "Offer" again (a changed rule's matches are new) and not "Greet", which had fired."""
    engine.deploy("oneline", {"types.drl": TYPES, "rules.drl": ONE_LINE % "Tea"}, force=True)
    session = engine.session_manager.open("oneline", kind="rest", on_deploy="follow")
    first = session.execute([{"op": "insert", "facts": [{"type": "Guest", "id": "g", "party": 1}]},
                             {"op": "fire", "max": -1}])
    assert sorted(a["params"]["text"] for a in first.actions()) == ["Greet g", "Tea g"]
    engine.deploy("oneline", {"types.drl": TYPES, "rules.drl": ONE_LINE % "Cake"}, force=True)
    again = session.execute([{"op": "fire", "max": -1}])
    assert [a["params"]["text"] for a in again.actions()] == ["Cake g"]
    session.close()


def test_rule_fingerprints_take_each_rule_alone_however_it_is_laid_out():
    one_line = 'rule "A" when Guest() then x(); end\nrule "B" when Guest() then y(); end\n'
    laid_out = 'rule "A"\nwhen\n  Guest()\nthen\n  x();\nend\n\nrule "B" when Guest() then z(); end\ndeclare T end\n'
    first, second = rule_fingerprints([one_line]), rule_fingerprints([laid_out])
    assert set(first) == set(second) == {"A", "B"}
    assert first["A"] == second["A"] and first["B"] != second["B"]


STACKED = """package org.printeps.sess;
import org.printeps.gateway.Actions;
global Actions actions;
rule "Main" when $g : Guest() then actions.say("pepper", "Main " + $g.getId()); end
rule "InA" agenda-group "a" when $g : Guest() then actions.say("pepper", "A " + $g.getId()); end
rule "InB" agenda-group "b" when $g : Guest() then actions.say("pepper", "B " + $g.getId()); end
"""


def test_a_move_keeps_the_whole_focus_stack(engine):
    """Groups pushed under the focus (set_focus a, then b, not fired yet) still fire after it, in
    order, once the session moved to a new version: the move carries the stack, not only its top."""
    engine.deploy("stackmove", {"types.drl": TYPES, "rules.drl": STACKED}, force=True)
    session = engine.session_manager.open("stackmove", kind="rest")
    session.execute([{"op": "insert", "facts": [{"type": "Guest", "id": "g", "party": 1}]},
                     {"op": "set_focus", "group": "a"}, {"op": "set_focus", "group": "b"}])
    engine.deploy("stackmove", {"types.drl": TYPES, "rules.drl": STACKED, "extra.drl": "package org.printeps.sess;\n"},
                  force=True)
    assert session.version == 2
    answer = session.execute([{"op": "fire", "max": -1}])
    assert [a["params"]["text"] for a in answer.actions() if a["module"] == "say"] == ["B g", "A g", "Main g"]
    session.close()


def _reception_files() -> dict[str, str]:
    from pathlib import Path

    folder = Path(__file__).resolve().parents[2] / "rules" / "drl" / "reception"
    return {p.relative_to(folder).as_posix(): p.read_text() for p in folder.rglob("*") if p.is_file()}


RECEPTION_PAIR = [{"type": "Entrance", "id": "entrance", "number_of_customers": 2},
                  {"type": "Customer", "id": "c1", "age": 30, "gender": "female", "entrance": "entrance"},
                  {"type": "Customer", "id": "c2", "age": 40, "gender": "female", "entrance": "entrance"},
                  {"type": "Robot", "id": "pepper", "position": "entrance"}]


@pytest.mark.parametrize("change", ["deploy", "rollback"])
def test_a_moved_session_fires_what_a_fresh_one_fires(engine, change):
    """Issue 32: a follow session of Entrance(2) and two Customers, moved before it fired, fired
    only "Adult, Adult": "Pair" arises only once "Adult" has typed the customers (a ``not`` over
    them), over the Entrance alone, which came across unchanged — it was refused as "already fired"."""
    files = _reception_files()
    engine.deploy("recv", files, force=True)
    engine.deploy("recv", {**files, "extra.drl": "package org.printeps.rules.reception;\n"}, force=True)
    fresh = engine.session_manager.open("recv", kind="rest")
    fresh.execute([{"op": "insert", "facts": RECEPTION_PAIR}])
    expected = [f["rule"] for f in fresh.execute([{"op": "fire", "max": -1}]).fired()]
    assert expected[:4] == ["Adult", "Adult", "Pair", "Greet a pair"], expected
    session = engine.session_manager.open("recv", kind="rest")
    session.execute([{"op": "insert", "facts": RECEPTION_PAIR}])
    if change == "deploy":
        engine.deploy("recv", {**files, "extra.drl": "package org.printeps.rules.reception;\n// v3\n"}, force=True)
    else:
        engine.rollback("recv", 1)
    assert session.version == (3 if change == "deploy" else 1), session.pinned_reason
    assert [f["rule"] for f in session.execute([{"op": "fire", "max": -1}]).fired()] == expected
    for s in (fresh, session):
        s.close()


def _shape_files(shape: str, seed: int) -> dict[str, str]:
    """Four rules of ``shape`` among three of random shapes (some modify facts: matches arise
    after the move), the random generator's types with the vip field."""
    import random

    from test_incremental import HEADER, TYPES as INC_TYPES, random_rule

    rng = random.Random(seed)
    rules = [random_rule(rng, f"{shape} {k}", True, shape=shape) for k in range(4)]
    rules += [random_rule(rng, f"other {k}", True) for k in range(3)]
    rng.shuffle(rules)
    return {"types.drl": INC_TYPES.format(extra="\n    vip: boolean"), "a.drl": HEADER + "\n".join(rules)}


def _facts(seed: int) -> list[dict]:
    import random

    rng = random.Random(seed)
    facts = [{"type": "Customer", "id": f"c{c}", "age": rng.choice([25, 70, rng.randint(5, 90)]),
              "tier": rng.choice(["gold", "silver", "basic"]), "vip": rng.random() < 0.5} for c in range(4)]
    facts += [{"type": "Order", "id": f"o{o}", "customer": f"c{rng.randrange(4)}", "amount": float(rng.randint(1, 1000))}
              for o in range(5)]
    rng.shuffle(facts)
    return facts


def _run(session, facts: list[dict], first_max: int, move) -> list[tuple[str, str]]:
    """Half the facts, a fire of ``first_max`` rules, the other half, ``move()``, a fire of all."""
    half = len(facts) // 2
    session.execute([{"op": "insert", "facts": facts[:half]}, {"op": "fire", "max": first_max}])
    session.execute([{"op": "insert", "facts": facts[half:]}])
    move()
    answer = session.execute([{"op": "fire", "max": -1}])
    return [(a["rule"], str(a["params"])) for a in answer.actions()]


def test_a_move_with_unchanged_rules_is_invisible_on_every_random_rule_shape(engine):
    """For every shape the random generator makes: a session moved to a version whose rules did
    not change, with facts fired and pending, fires what a session that did not move fires."""
    from test_incremental import SHAPES

    for k, shape in enumerate(SHAPES):
        name = f"shape{k}"
        files = _shape_files(shape, k)
        engine.deploy(name, files, force=True)
        for seed, first_max in ((k, -1), (k + 100, 2), (k + 200, 0)):
            facts = _facts(seed)
            still = engine.session_manager.open(name, kind="rest", on_deploy="pin")
            expected = _run(still, facts, first_max, lambda: None)
            moving = engine.session_manager.open(name, kind="rest")
            version = moving.version
            actual = _run(moving, facts, first_max, lambda: engine.deploy(
                name, {**files, "extra.drl": f"package org.printeps.inc;\n// {seed}\n"}, force=True))
            assert moving.version == version + 1, (shape, moving.pinned_reason)
            # the same matches fire; those of one rule and salience in an order Drools leaves open
            assert sorted(actual) == sorted(expected), (shape, seed, first_max, files["a.drl"])
            for s in (still, moving):
                s.close()
        engine.delete(name)


def test_deploys_with_a_session_open_keep_a_bounded_memo_of_versions(engine, monkeypatch):
    """bench/soak.py (a deploy a minute, sessions open): each move remembered the unchanged rules of
    its (old, new) pair and each build its kmodule declarations, for ever. Now only the last few;
    a forgotten one is recomputed, so the session still follows and fires."""
    from gateway.engine import engine as engine_module

    monkeypatch.setattr(engine_module, "UNCHANGED_KEPT", 3, raising=False)
    monkeypatch.setattr(engine_module, "DECLARED_KEPT", 3, raising=False)
    engine.deploy("memo", files("Seat0"), force=True)
    session = engine.session_manager.open("memo", kind="rest")
    for n in range(1, 8):
        engine.deploy("memo", files(f"Seat{n}"), force=True)
        assert session.version == n + 1  # the session moved: its unchanged rules were asked for
    assert len(engine._unchanged) <= 3 and len(engine._declared) <= 3
    engine.deploy("memo", files("Seat0"), force=True)  # an evicted content again (the compile cache has it)
    assert engine.declared_sessions("memo") is not None
    answer = session.execute([{"op": "insert", "facts": [{"type": "Guest", "id": "g", "party": 1}]},
                              {"op": "fire", "max": -1}])
    assert [a["params"]["text"] for a in answer.actions() if a["module"] == "say"] == ["Seat0 g"]
    session.close()
