"""The shapes plain rules took on for issue 30 (bound fields, ``in``/``not in``, ``matches``,
``not``/``exists``, ``from accumulate`` count/sum/min/max, agenda-group, activation-group,
auto-focus, no-loop, lock-on-active, date-effective/expires), built at run time against a real JVM:
every request fires the same rules, in the same order, with the same texts, as the same rules
compiled by Drools' executable model; and plain and compiled rules of the same constraints share
their nodes without losing a firing (Drools' alpha hashing keeps one node per hashed value).

No timing assertions: speed is measured by bench/growth_bench.py.
"""

from __future__ import annotations

import json
import random
import sys
from pathlib import Path

import pytest

from gateway.engine import compiler, incremental
from gateway.engine.compiler import CompileOptions
from gateway.engine.results import encode_facts

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench" / "peers"))
from business_rules import BusinessRules

TYPES = """package org.printeps.shapes;
import org.printeps.gateway.Actions;
global Actions actions;

declare Customer
    id: String
    age: int
    tier: String
end

declare Order
    id: String
    customer: String
    amount: double
end
"""

#: Rules of the new plain shapes (name -> DRL body after the name), each meant to build plain.
PLAIN = {
    "in": 'when $c: Customer(tier in ("gold", "vip"), age >= 20) then actions.say("bot", "in " + $c.getId());',
    "not in": 'when $c: Customer(tier not in ("gold"), age in (30, 40, 50, 61, 70)) then actions.say("bot", "not in " + $c.getId());',
    "matches": 'when $c: Customer(id matches "c[0-4]", tier not matches "v.*") then actions.say("bot", "matches " + $c.getId());',
    "join bound": ('when $c: Customer($cid : id, age > 25)\n $o: Order(customer == $cid, amount > 100.0)\n'
                   'then actions.say("bot", "join " + $c.getId() + "/" + $o.getId());'),
    "bound int": 'when Customer($age : age, tier == "gold")\n Customer(age > $age, $id : id)\nthen actions.say("bot", "older " + $id + " " + $age);',
    "not": 'when $c: Customer($cid : id)\n not Order(customer == $cid)\nthen actions.say("bot", "no order " + $c.getId());',
    "not parens": ('when $c: Customer($cid : id, tier == "gold")\n not( Order(customer == $cid, amount > 500.0) )\n'
                   'then actions.say("bot", "no big order " + $cid);'),
    "exists": 'when $c: Customer($cid : id)\n exists Order(customer == $cid, amount < 200.0)\nthen actions.say("bot", "small " + $c.getId());',
    "count": ('when $c: Customer($cid : id)\n Number( intValue >= 2 ) from accumulate( Order( customer == $cid, $a : amount ), count( 1 ) )\n'
              'then actions.say("bot", "count " + $c.getId());'),
    "sum": ('when $c: Customer($cid : id)\n $t : Number( doubleValue > 300.0 ) from accumulate( Order( customer == $cid, $a : amount ), sum( $a ) )\n'
            'then actions.say("bot", "sum " + $c.getId() + " " + $t);'),
    "min": ('when $c: Customer($cid : id)\n $m : Number( doubleValue < 150.0 ) from accumulate( Order( customer == $cid, $a : amount ), min( $a ) )\n'
            'then actions.say("bot", "min " + $cid + " " + $m);'),
    "max": ('when $c: Customer($cid : id, age < 70)\n Number( doubleValue >= 400, doubleValue < 900.0 ) from accumulate( Order( customer == $cid, $a : amount ), max( $a ) )\n'
            'then actions.say("bot", "max " + $cid);'),
    "group a": ('agenda-group "a" auto-focus true salience 5\nwhen Customer(tier == "vip", $id : id)\n'
                'then actions.say("bot", "group a " + $id);'),
    "lock": 'agenda-group "a" lock-on-active true\nwhen $c: Customer(tier == "vip")\nthen actions.say("bot", "lock " + $c.getId());',
    "act 1": 'activation-group "one" salience 10\nwhen Customer(age > 10)\nthen actions.say("bot", "act 1");',
    "act 2": 'activation-group "one"\nwhen Customer(age > 10)\nthen actions.say("bot", "act 2");',
    "no loop": 'no-loop true\nwhen $c: Customer(age > 5)\nthen actions.say("bot", "no loop " + $c.getId());',
    "past": 'date-effective "01-Jan-2020"\nwhen $c: Customer(age > 50)\nthen actions.say("bot", "past " + $c.getId());',
    "future": 'date-effective "01-Jan-2099"\nwhen Customer()\nthen actions.say("bot", "future");',
    "expired": 'date-expires "01-Jan-2001"\nwhen Customer()\nthen actions.say("bot", "expired");',
    "expires later": 'date-expires "01-JAN-2099" no-loop\nwhen $c: Customer(tier == "silver")\nthen actions.say("bot", "later " + $c.getId());',
    "unfocused": 'agenda-group "b"\nwhen Customer()\nthen actions.say("bot", "unfocused");',
}

#: Compiled rules (their then-parts modify facts) that make the attributes matter.
COMPILED = {
    "promote in a": ('agenda-group "a" auto-focus true\nwhen $c: Customer(age > 40, tier == "gold")\n'
                     'then modify($c) { setTier("vip") }'),
    "promote": 'salience 20\nwhen $c: Customer(age > 60, tier == "silver")\nthen modify($c) { setTier("gold") }',
}


#: Then-parts with static calls of java.lang classes (issue 30), each resolved as javac resolves it:
#: widening (max(long, long) for an int and a long), boxing (a bound Integer into an int), variable
#: arity (format, join, the Actions global's call(String, Object...)), the most specific overload
#: (valueOf(Object) for a String that may be null, not valueOf(char[])). The texts tell the
#: overloads apart: an int, a long and a double print differently.
STATIC = {
    "format": ('when $c: Customer(age > 20)\nthen actions.say("bot", "f|" + String.format("%s|%d", $c.getId(), '
               'Math.max($c.getAge(), 1L)));'),
    "widen to double": 'when $c: Customer(age < 40)\nthen actions.say("bot", "w " + Math.max($c.getAge(), 2.5) + " " + Double.toString($c.getAge()));',
    "boxed int": ('when Customer($age : age, $id : id, tier == "gold")\n'
                  'then actions.say("bot", "b " + $id); actions.say("bot", "b " + Math.max($age, 7) + " " + Long.valueOf($age) + " " + Integer.toHexString($age));'),
    "varargs boxing": ('when $c: Customer($id : id)\n $o: Order(customer == $id)\n'
                       'then actions.say("bot", String.format("%s %s %.2f %s", $id, $c.getAge(), $o.getAmount(), 3));'),
    "join": 'when $c: Customer(age > 50)\nthen actions.say("bot", String.join("/", $c.getId(), "x", String.valueOf($c.getAge())));',
    "null text": 'when $c: Customer(age > 10)\nthen actions.say("bot", "t " + String.valueOf($c.getTier()) + " " + String.format("%s", $c.getTier()));',
    "long literal": 'when $c: Customer(age > 60)\nthen actions.say("bot", "l " + Math.abs(-3L) + " " + Math.round(2.5) + " " + Long.toString(255L, 16) + " " + Math.floorMod($c.getAge(), 7));',
    "compare": ('when $c: Customer($id : id)\n $o: Order(customer == $id)\n'
                'then actions.say("bot", "c " + Double.compare($o.getAmount(), 100) + " " + Integer.compare($c.getAge(), 30));'),
    "global varargs": ('when $c: Customer(age > 30)\nthen actions.call("note", "who", $c.getId(), "age", $c.getAge(), '
                       '"big", Math.max($c.getAge(), 1L), "half", Math.max(0.5, 0));'),
}


def drl(rules: dict[str, str]) -> str:
    return "package org.printeps.shapes;\n\n" + "\n".join(f'rule "{name}"\n{body}\nend\n' for name, body in rules.items())


@pytest.fixture()
def options(tmp_path) -> CompileOptions:
    incremental.reset()
    yield CompileOptions(cache_dir=str(tmp_path / "units"))
    incremental.reset()


def compiled_only() -> CompileOptions:
    return CompileOptions(incremental=True, disk_cache=False, plain_rules=False)


def fire(compiled, facts: list[dict]) -> dict:
    answer = json.loads(str(compiled.runner.fire(encode_facts(facts, 10_000), 10_000, False, True)))
    assert answer["ok"], answer
    return {"actions": [(a["rule"], a.get("module"), json.dumps(a["params"], sort_keys=True)) for a in answer["actions"]],
            "fired": [f["rule"] for f in answer["fired"]]}


def fire_raw(compiled, facts: list[dict]) -> dict:
    """The runner's whole answer, refusals included."""
    return json.loads(str(compiled.runner.fire(encode_facts(facts, 10_000), 10_000, False, True)))


def fire_fresh(compiled, facts: list[dict]) -> dict:
    """As :func:`fire`, in a session of its own (a new Runner's first session is a new one)."""
    from gateway.base import jvm

    return fire(type("Fresh", (), {"runner": jvm.helper_class("Runner")(compiled.kbase)}), facts)


def random_facts(rng: random.Random) -> list[dict]:
    customers = [{"type": "Customer", "id": f"c{i}", "age": rng.randint(5, 80),
                  **({"tier": rng.choice(["gold", "silver", "vip"])} if rng.random() < 0.85 else {})}
                 for i in range(rng.randint(1, 6))]
    orders = [{"type": "Order", "id": f"o{n}", "customer": f"c{rng.randint(0, 6)}",
               "amount": float(rng.randrange(0, 1000, 25))} for n in range(rng.randint(0, 8))]
    return customers + orders


def test_each_new_shape_builds_plain_and_fires_as_compiled(options):
    files = {"types.drl": TYPES, "rules.drl": drl({**PLAIN, **COMPILED})}
    plain = compiler.compile_files(files, "shapes", options)
    assert (plain.stats.rules_built, plain.stats.rules_compiled) == (len(PLAIN), len(COMPILED))
    assert plain.runner.reusesSessions()  # agenda groups, auto-focus, activation groups, lock-on-active
    compiled = compiler.compile_files(files, "shapes", compiled_only())
    assert compiled.stats.rules_built == 0
    rng = random.Random(30)
    seen: set[str] = set()
    for k in range(60):
        facts = random_facts(rng)
        got = fire(plain, facts)
        assert got == fire(compiled, facts), (k, facts)
        assert got == fire_fresh(plain, facts), (k, facts)  # a reused session fires as a fresh one
        seen.update(got["fired"])
        assert "act 1" not in got["fired"] or "act 2" not in got["fired"]  # one of an activation group
    # the requests reached every shape that can fire; these never do
    assert seen == set(PLAIN) - {"future", "expired", "unfocused", "act 2"} | set(COMPILED)


def test_then_part_static_calls_build_plain_and_fire_as_compiled(options):
    """Static calls with widening, boxing, varargs and overloads: the same firings, order and texts
    (the chosen overloads print differently) plain as compiled."""
    files = {"types.drl": TYPES, "rules.drl": drl(STATIC)}
    assert compiler.plain_split(files) == {"plain": len(STATIC)}
    plain = compiler.compile_files(files, "static", options)
    assert (plain.stats.rules_built, plain.stats.rules_compiled) == (len(STATIC), 0)
    compiled = compiler.compile_files(files, "static", compiled_only())
    rng = random.Random(31)
    seen: set[str] = set()
    for k in range(60):
        facts = random_facts(rng)
        got = fire(plain, facts)
        assert got == fire(compiled, facts), (k, facts)
        seen.update(got["fired"])
    assert seen == set(STATIC)
    texts = {text for _, _, text in fire(plain, [{"type": "Customer", "id": "c1", "age": 70, "tier": "gold"}])["actions"]}
    assert '{"robot": "bot", "text": "f|c1|70"}' in texts  # format's %d took the long max(70, 1L)
    assert '{"robot": "bot", "text": "l 3 3 ff 0"}' in texts
    assert '{"age": 70, "big": 70, "half": 0.5, "who": "c1"}' in texts  # call(String, Object...) on the global


@pytest.mark.parametrize("then, reason", [
    ('actions.say("bot", System.getProperty("user.home"));', "System, not a java.lang class the rule policy allows"),
    ('actions.say("bot", "x" + Thread.currentThread());', "Thread, not a java.lang class"),
    ('actions.say("bot", "x" + String.class);', "class"),
    ('actions.say("bot", "x" + Math.max(1, 2).toString());', "a call on the result of a call"),
    ('actions.say("bot", "x" + java.lang.Math.max(1, 2));', "a call on java"),
])
def test_static_calls_the_rule_policy_refuses_are_never_plain(then, reason):
    """A then-part's static call goes plain only on a java.lang class the rule policy allows an
    author to name (and never a reflection member): anything else is the compiler's (and, for an
    author, the policy's refusal)."""
    files = {"types.drl": TYPES, "rules.drl": drl({"r": f"when $c: Customer()\nthen {then}"})}
    split = compiler.plain_split(files)
    assert "plain" not in split and reason in next(iter(split)), split


@pytest.mark.parametrize("body", [
    # an accumulate result's static type is the generated code's (a Number): not resolved here
    ('when Customer($c : id)\n $t : Number( doubleValue > 1 ) from accumulate( Order( customer == $c, $a : amount ), sum( $a ) )\n'
     'then actions.say("bot", String.valueOf($t));'),
    # a declared type named like a java.lang class hides it
    'when $c: Customer()\nthen actions.say("bot", "x" + Math.max(1, 2));',
    # no method applies: javac's error, with file and line
    'when $c: Customer()\nthen actions.say("bot", "x" + Math.max("a", 2));',
])
def test_static_calls_javac_would_type_otherwise_go_to_the_compiler(body, options):
    types = TYPES + "\ndeclare Math\n    id: String\nend\n" if "Math.max(1, 2)" in body else TYPES
    files = {"types.drl": types, "rules.drl": drl({"r": body})}
    try:
        built = compiler.compile_files(files, "refused", options)
    except compiler.CompileFailed:
        return  # the compiler refuses it too (with file, line and column): never a plain rule
    assert (built.stats.rules_built, built.stats.rules_compiled) == (0, 1)


def test_a_null_field_fails_in_and_matches_and_passes_their_negations(options):
    files = {"types.drl": TYPES, "rules.drl": drl({
        "in": 'when Customer(tier in ("gold")) then actions.say("bot", "in");',
        "not in": 'when Customer(tier not in ("gold")) then actions.say("bot", "not in");',
        "matches": 'when Customer(tier matches ".*") then actions.say("bot", "matches");',
        "not matches": 'when Customer(tier not matches "g.*") then actions.say("bot", "not matches");',
    })}
    plain = compiler.compile_files(files, "nulls", options)
    assert plain.stats.rules_built == 4
    facts = [{"type": "Customer", "id": "c0", "age": 3}]
    assert sorted(fire(plain, facts)["fired"]) == ["not in", "not matches"]
    assert fire(plain, facts) == fire(compiler.compile_files(files, "nulls", compiled_only()), facts)


def test_a_regular_expression_is_compiled_once_and_a_bad_one_fails_as_drools_does(options):
    """``matches`` compiles its expression when the rule is built (Drools' operator compiles it at
    every test); one that does not compile fails each fire the way the compiled rule's does."""
    good = {"types.drl": TYPES, "rules.drl": drl({
        "suffix": 'when $c: Customer(id matches ".*[0-4]") then actions.say("bot", "low " + $c.getId());',
        "letters": 'when $c: Customer(tier matches "g[a-z]+d") then actions.say("bot", "word " + $c.getId());',
    })}
    plain = compiler.compile_files(good, "regex", options)
    assert plain.stats.rules_built == 2
    facts = [{"type": "Customer", "id": f"c{k}", "age": 30, "tier": tier} for k, tier in enumerate(["gold", "good", "g-d", "gd"] * 2)]
    assert fire(plain, facts) == fire(compiler.compile_files(good, "regex", compiled_only()), facts)
    assert fire(plain, facts)["fired"].count("letters") == 4
    bad = {"types.drl": TYPES, "rules.drl": drl({"bad": 'when Customer(tier matches "g[") then actions.say("bot", "x");'})}
    try:
        compiled_bad = compiler.compile_files(bad, "bad regex", compiled_only())
    except compiler.CompileFailed:
        return  # refused when compiled: nothing to compare
    plain_bad = compiler.compile_files(bad, "bad regex", options)
    assert plain_bad.stats.rules_built == 1
    answer = fire_raw(plain_bad, facts)
    assert answer == fire_raw(compiled_bad, facts) and answer["ok"] is False and "g[" in answer["message"]


@pytest.mark.parametrize("body", [
    'when Order(amount in (1.0, 2.0)) then actions.say("bot", "x");',  # in on a double: boxing is the compiler's
    'when Customer(age in ("a")) then actions.say("bot", "x");',
    'when Customer(age matches "1.*") then actions.say("bot", "x");',
    'when Customer($a : age)\n Customer(tier == $a) then actions.say("bot", "x");',
    'when Customer($c : id)\n Number( intValue > 1.5 ) from accumulate( Order( customer == $c ), count( 1 ) ) then actions.say("bot", "x");',
    'when Customer($c : id)\n Number( doubleValue > 1 ) from accumulate( Order( customer == $c, $i : id ), min( $i ) ) then actions.say("bot", "x");',
    'when Customer($c : id)\n Long( intValue > 1 ) from accumulate( Order( customer == $c ), count( 1 ) ) then actions.say("bot", "x");',
])
def test_shapes_the_java_side_cannot_build_exactly_go_to_the_compiler(body, options):
    files = {"types.drl": TYPES, "rules.drl": drl({"r": body})}
    try:
        built = compiler.compile_files(files, "refused", options)
    except compiler.CompileFailed:
        return  # the compiler refuses it too (with file, line and column): never a plain rule
    assert (built.stats.rules_built, built.stats.rules_compiled) == (0, 1)


def test_business_rules_built_plain_fire_as_compiled_and_share_nodes_with_compiled_copies(options):
    """The second generator's shapes, plain against compiled; then a set where a third of the rules
    have compiled copies of the same constraints (a then-part that is not plain): equal constraints
    must be one node, or a hashed alpha value keeps only one of them and a rule never fires."""
    rules = BusinessRules(7, 120, regions=6, segments=3, purposes=3, domains=3)
    files = rules.drl_files()
    plain = compiler.compile_files(files, "business", options)
    assert plain.stats.rules_built >= 0.85 * 120
    compiled = compiler.compile_files(files, "business", compiled_only())
    copies = [rules.rule(i) for i in range(0, 120, 3)]
    mixed_files = dict(files)
    mixed_files["mixed.drl"] = "package org.printeps.business;\n\n" + "\n".join(
        r.drl.replace(f'rule "{r.name}"', f'rule "copy {r.index}"').replace(
            f'actions.say("bot", "{r.name}");', f'actions.say("bot", "copy " + ({r.index}));') for r in copies)
    mixed = compiler.compile_files(mixed_files, "mixed", options)
    assert mixed.stats.rules_compiled >= len(copies)
    reference = compiler.compile_files(mixed_files, "mixed", compiled_only())
    for k in range(8):
        facts = rules.facts(k, applicants=4, loans=6)
        expected = {name: len(texts) for name, texts in rules.expected(facts).items()}
        got = fire(plain, facts)
        assert got == fire(compiled, facts), k
        assert {r: got["fired"].count(r) for r in set(got["fired"])} == expected, k
        assert fire(mixed, facts) == fire(reference, facts), k



def test_plain_rules_read_fields_through_generated_getters_not_reflection(options):
    """The declared types' getters are called directly (a generated function, as the executable
    model's lambdas call them; reflection cost 14% of a 10,000-rule business request), and each
    reader returns what its getter returns. A JDK class's getter (its module is not open to the
    helpers) is read by reflection, still right, and its exception reaches the caller as itself."""
    from gateway.base import jvm

    plain = compiler.compile_files({"types.drl": TYPES, "rules.drl": drl({"in": PLAIN["in"]})}, "readers", options)
    assert plain.stats.rules_built == 1
    readers = jvm.helper_class("PlainRules")
    customer = plain.kbase.getFactType("org.printeps.shapes", "Customer")
    fact = customer.newInstance()
    customer.set(fact, "id", "c7")
    customer.set(fact, "age", jvm.jclass("java.lang.Integer").valueOf(41))
    for getter, value in (("getId", "c7"), ("getAge", 41), ("getTier", None)):
        method = fact.getClass().getMethod(getter)
        assert readers.readsDirectly(method), getter
        got = readers.reader(method).apply(fact)
        assert (got if got is None else type(value)(got)) == value, getter
    length = jvm.jclass("java.lang.String").class_.getMethod("length")
    assert not readers.readsDirectly(length)
    assert int(readers.reader(length).apply(jvm.jclass("java.lang.String")("four"))) == 4
    empty = jvm.jclass("java.util.Optional")
    with pytest.raises(Exception, match="NoSuchElementException"):
        readers.reader(empty.class_.getMethod("get")).apply(empty.empty())
