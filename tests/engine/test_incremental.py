"""Incremental builds against a real JVM with Drools: a rule set built from cached units after any
sequence of edits fires exactly as a one-unit build of the same text; only what changed compiles;
compiled sets move between processes; resource limits are server errors.

No timing assertions (the machine is shared): speed is measured by bench/growth_bench.py.
"""

from __future__ import annotations

import json
import random
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from gateway.engine import build, compiler, incremental
from gateway.engine.artifacts import (
    IncompatibleArtifact,
    export_compiled,
    load_compiled,
)
from gateway.engine.build import CompileOptions
from gateway.engine.errors import CompileFailed, CompileResourceError, says_out_of_memory
from gateway.engine.results import encode_facts
from gateway.engine.warmup import literal_facts, plain_facts, warm

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench" / "peers"))
import growth_rules

HEADER = "package org.printeps.inc;\n\n"
TYPES = """package org.printeps.inc;
import org.printeps.gateway.Actions;
global Actions actions;

declare Customer
    id: String
    age: int
    tier: String{extra}
end

declare Order
    id: String
    customer: String
    amount: double
end

function String band(double amount) {{ return amount > 500 ? "big" : "small"; }}

query bigSpenders(double $min)
    Order($min <= amount)
end
"""


@pytest.fixture()
def options(tmp_path) -> CompileOptions:
    """A unit cache of this test's own (memory and disk), so tests never see each other's units."""
    incremental.reset()
    yield CompileOptions(cache_dir=str(tmp_path / "units"))
    incremental.reset()


def rebuilt_rules(stats: incremental.BuildStats) -> int:
    """Rules a build made anew: compiled to Java, or (plain shapes) built at run time."""
    return stats.rules_compiled + stats.rules_built


def whole(files: dict[str, str]) -> compiler.CompiledRuleSet:
    return compiler.compile_files(files, "whole", CompileOptions(incremental=False, disk_cache=False))


def fire(compiled, facts) -> dict:
    answer = json.loads(str(compiled.runner.fire(encode_facts(facts, 10_000), 10_000, False, True)))
    assert answer["ok"], answer
    return {"actions": [(a["rule"], a["module"], a["params"]) for a in answer["actions"]],
            "fired": [f["rule"] for f in answer["fired"]]}


# --------------------------------------------------------------------------- random rule sets and edits


#: Every rule shape :func:`random_rule` makes (the last three only when asked for / with the vip field).
SHAPES = ["age", "tier", "amount", "join", "accumulate", "modify", "function", "absent", "plain tier", "plain join",
          "plain accumulate", "plain number join", "plain same age", "query", "vip", "plain vip"]


def random_rule(rng: random.Random, name: str, vip_field: bool, queries: bool = True, shape: str | None = None) -> str:
    """One rule of a random shape (or of ``shape``); some modify facts, so firing order and
    inference both matter."""
    shape = shape or rng.choice(SHAPES[:13] + (["query"] if queries else []) + (["vip", "plain vip"] if vip_field else []))
    salience = f"salience {rng.randint(-5, 5)}\n" if rng.random() < 0.3 else ""
    say = f'actions.say("bot", "{name}");'
    if shape == "age":
        when = f"$c: Customer(age >= {rng.randint(0, 60)}, age < {rng.randint(30, 90)})"
        then = say
    elif shape == "tier":
        when = f'$c: Customer(tier == "{rng.choice(["gold", "silver", "vip"])}")'
        then = f'actions.say("bot", "{name} " + $c.getId());'
    elif shape == "amount":
        when = f"$o: Order(amount > {rng.randint(0, 900)}.0)"
        then = f'actions.say("bot", "{name} " + $o.getId());'
    elif shape == "join":
        when = f"$c: Customer(age > {rng.randint(10, 50)})\n    $o: Order(customer == $c.id, amount > {rng.randint(0, 500)}.0)"
        then = f'actions.say("bot", "{name} " + $c.getId() + "/" + $o.getId());'
    elif shape == "accumulate":
        when = (f"$c: Customer()\n    accumulate(Order(customer == $c.id, $a: amount); $t: sum($a); "
                f"$t > {rng.randint(0, 1200)}.0)")
        then = f'actions.say("bot", "{name} " + $c.getId());'
    elif shape == "modify":
        when = f'$c: Customer(age > {rng.randint(20, 70)}, tier != "vip")'
        then = f'modify($c) {{ setTier("vip") }}\n    {say}'
    elif shape == "function":
        when = f"$o: Order(amount > {rng.randint(0, 900)}.0)"
        then = f'actions.say("bot", "{name} " + band($o.getAmount()));'
    elif shape == "absent":  # a not after a first pattern: deleting facts may activate it
        when = f"$c: Customer(age > {rng.randint(10, 60)})\n    not Order(customer == $c.id)"
        then = f'actions.say("bot", "{name} no order " + $c.getId());'
    elif shape == "plain tier":  # more plain shapes (gateway.engine.plain_rules); most of the above are plain too
        tier = rng.choice(["gold", "vip"])
        when = f'Customer(tier {rng.choice(["==", "!="])} "{tier}", age <= {rng.randint(20, 80)})'
        then = say + f' actions.say("kiosk", "{name} again");'
    elif shape == "plain join":
        when = (f'$o: Order(amount >= {rng.randint(0, 900)}.0)\n'
                f'    $c: Customer(id == $o.customer, age > {rng.randint(10, 50)}, tier != "vip")')
        then = say
    elif shape == "plain accumulate":
        when = (f'$c: Customer(tier == "{rng.choice(["gold", "silver", "vip"])}")\n'
                f'    accumulate(Order(customer == $c.id, amount > 100, $a: amount); $t: sum($a); '
                f'$t > {rng.randint(0, 1200)}.0)')
        then = say
    elif shape == "plain number join":
        when = (f'$o: Order(amount > {rng.randint(0, 500)})\n'
                f'    $p: Order(amount < $o.amount, customer == $o.customer, id != $o.id)')
        then = f'actions.say("bot", "{name} " + $o.getAmount() + " > " + $p.getAmount() + " " + $p.getId());'
    elif shape == "plain same age":
        when = f'$c: Customer(age >= {rng.randint(0, 60)})\n    $d: Customer(age == $c.age, id != $c.id)'
        then = f'actions.say("bot", "{name} " + $c.getAge() + $d.getId() + true + 2.50);'
    elif shape == "plain vip":
        when = f'Customer(vip == {rng.choice(["true", "false"])}, age > {rng.randint(10, 60)})'
        then = say
    elif shape == "query":
        when = f"?bigSpenders({rng.randint(100, 900)}.0;)\n    $c: Customer(age < {rng.randint(20, 80)})"
        then = f'actions.say("bot", "{name} " + $c.getId());'
    else:
        when = "$c: Customer(vip == true)"
        then = f'actions.say("bot", "{name} vip " + $c.getId());'
    return f'rule "{name}"\n{salience}when\n    {when}\nthen\n    {then}\nend\n'


class RandomSet:
    """A rule set of two rule files and the types file, edited at random."""

    def __init__(self, seed: int, queries: bool = True):
        self.rng = random.Random(seed)
        self.queries = queries
        self.vip = False
        self.counter = 0
        self.rules: dict[str, list[tuple[str, str]]] = {"a.drl": [], "b.drl": []}
        for file in self.rules:
            for _ in range(8):
                self.add(file)

    def new_name(self) -> str:
        self.counter += 1
        return f"rule {self.counter:03d}"

    def add(self, file: str | None = None) -> None:
        file = file or self.rng.choice(list(self.rules))
        name = self.new_name()
        position = self.rng.randint(0, len(self.rules[file]))
        self.rules[file].insert(position, (name, random_rule(self.rng, name, self.vip, self.queries)))

    def edit(self) -> str:
        """One random edit; returns its kind."""
        kind = self.rng.choice(["add", "change", "change", "remove", "type"])
        file = self.rng.choice(list(self.rules))
        if kind == "add" or (kind in ("change", "remove") and not self.rules[file]):
            self.add(file)
            return "add"
        if kind == "change":
            k = self.rng.randrange(len(self.rules[file]))
            name = self.rules[file][k][0]
            self.rules[file][k] = (name, random_rule(self.rng, name, self.vip, self.queries))
        elif kind == "remove":
            self.rules[file].pop(self.rng.randrange(len(self.rules[file])))
        else:  # a declared type changes: a field comes or goes (rules using it go with it)
            self.vip = not self.vip
            if not self.vip:
                for f in self.rules:
                    self.rules[f] = [(n, t) for n, t in self.rules[f] if "vip ==" not in t]
            else:
                self.add()
        return kind

    def files(self) -> dict[str, str]:
        extra = "\n    vip: boolean" if self.vip else ""
        out = {"types.drl": TYPES.format(extra=extra)}
        for file, rules in self.rules.items():
            out[file] = HEADER + "\n".join(text for _, text in rules)
        return out

    def facts(self) -> list[list[dict]]:
        rng = random.Random(7)
        sets = []
        for _ in range(4):
            facts = []
            for c in range(3):
                customer = {"type": "Customer", "id": f"c{c}", "age": rng.choice([25, 70, rng.randint(5, 90)]),
                            "tier": rng.choice(["gold", "silver", "basic"])}
                if self.vip:
                    customer["vip"] = rng.random() < 0.5
                facts.append(customer)
            facts += [{"type": "Order", "id": f"o{o}", "customer": f"c{rng.randrange(3)}",
                       "amount": float(rng.randint(1, 1000))} for o in range(4)]
            sets.append(facts)
        return sets


# Three random sets in the inner loop, all ten in the full run (make test).
@pytest.mark.parametrize("seed", [1, 2, 3, *(pytest.param(n, marks=pytest.mark.slow) for n in range(4, 11))])
def test_incremental_builds_fire_exactly_as_whole_builds_over_random_edits(options, seed):
    rule_set = RandomSet(seed)
    compiled = compiler.compile_files(rule_set.files(), "inc", options)
    assert compiled.stats.mode == "incremental"
    seen = {compiled.hash}
    for step in range(6):
        kind = rule_set.edit()
        files = rule_set.files()
        texts = _rule_texts(files)
        built = compiler.compile_files(files, "inc", options)
        if built.hash in seen:  # an edit that restored an earlier version: assembled from its plan
            kind = "restored"
            assert built.stats.mode == "plan"
        seen.add(built.hash)
        reference = whole(files)
        assert built.rule_count == reference.rule_count
        assert built.types == reference.types
        for facts in rule_set.facts():
            assert fire(built, facts) == fire(reference, facts), f"step {step} ({kind}) fires differently"
        # only what changed was compiled: a new or changed rule, or every rule naming a changed type
        if kind in ("add", "change"):
            assert rebuilt_rules(built.stats) == 1, (kind, built.stats)
        elif kind in ("remove", "restored"):
            assert rebuilt_rules(built.stats) == 0, (kind, built.stats)
        else:
            naming_customer = sum(1 for text in texts.values() if "Customer" in text)
            # the rules naming Customer (+ the rule a new field brings); none when every such rule was
            # built before against the same declaration (the field came and went again)
            assert 0 <= rebuilt_rules(built.stats) <= naming_customer + 1, built.stats
            assert rebuilt_rules(built.stats) < built.rule_count or naming_customer == built.rule_count


def _rule_texts(files: dict[str, str]) -> dict[str, str]:
    """Rule name -> text, of the generated files (for counting what a type change touches)."""
    out = {}
    for file, text in files.items():
        for block in text.split('rule "')[1:]:
            out[block.split('"', 1)[0]] = block
    return out


def test_a_declared_type_change_rebuilds_exactly_the_rules_that_use_it(options):
    files = {"types.drl": TYPES.format(extra=""),
             "c.drl": HEADER + "".join(f'rule "c{i}" when Customer(age > {i}) then actions.say("b", "c{i}"); end\n'
                                       for i in range(5)),
             "o.drl": HEADER + "".join(f'rule "o{i}" when Order(amount > {i}.0) then actions.say("b", "o{i}"); end\n'
                                       for i in range(5))}
    compiler.compile_files(files, "types", options)
    changed = dict(files, **{"types.drl": TYPES.format(extra="\n    vip: boolean")})
    built = compiler.compile_files(changed, "types", options)
    assert rebuilt_rules(built.stats) == 5  # the rules naming Customer; the Order rules are reused
    assert built.types["Customer"]["vip"] == "boolean"
    facts = [{"type": "Customer", "id": "x", "age": 3, "tier": "gold", "vip": True}, {"type": "Order", "id": "o", "customer": "x", "amount": 2.5}]
    assert fire(built, facts) == fire(whole(changed), facts)


def test_a_type_change_that_breaks_a_rule_is_reported_in_the_rule_file(options):
    files = {"types.drl": TYPES.format(extra="\n    vip: boolean"),
             "r.drl": HEADER + 'rule "vip"\nwhen\n    $c: Customer(vip == true)\nthen\n    actions.say("b", "vip");\nend\n'}
    compiler.compile_files(files, "broken", options)
    with pytest.raises(CompileFailed) as failed:
        compiler.compile_files(dict(files, **{"types.drl": TYPES.format(extra="")}), "broken", options)
    error = failed.value.errors[0]
    assert (error.file, error.line) == ("r.drl", 5) and "vip" in error.message


def test_errors_in_units_carry_the_authors_positions(options):
    """A bad rule compiled in a unit of its own is reported where a whole build reports it."""
    good = growth_rules.drl_files(60)
    broken = dict(good)
    lines = broken["rules_000.drl"].split("\n")
    target = next(i for i, line in enumerate(lines) if "r00031" in line and "rule" in line)
    lines[target + 2] = lines[target + 2].replace("Order(", "Ordr(").replace("Customer(", "Custmer(")
    broken["rules_000.drl"] = "\n".join(lines)
    compiler.compile_files(good, "pos", options)  # every other rule is cached: only the broken one compiles
    with pytest.raises(CompileFailed) as incremental_error:
        compiler.compile_files(broken, "pos", options)
    with pytest.raises(CompileFailed) as whole_error:
        whole(broken)
    got = [(e.file, e.line, e.column) for e in incremental_error.value.errors]
    assert got == [(e.file, e.line, e.column) for e in whole_error.value.errors]
    assert got[0][:2] == ("rules_000.drl", target + 3)


def test_duplicate_rule_names_across_units_are_reported(options):
    files = {"types.drl": TYPES.format(extra=""),
             "a.drl": HEADER + 'rule "same" when Customer() then actions.say("b", "a"); end\n',
             "b.drl": HEADER + '\n\nrule "same" when Order() then actions.say("b", "b"); end\n'}
    with pytest.raises(CompileFailed) as failed:
        compiler.compile_files(files, "dup", options)
    error = failed.value.errors[0]
    assert (error.file, error.line) == ("b.drl", 5) and "Duplicate rule name" in error.message


def test_the_dsl_reception_set_builds_in_units_and_fires_as_a_whole_build(options):
    from gateway.engine.ruleset import read_folder

    files = read_folder(ROOT / "rules" / "drl" / "reception")
    built = compiler.compile_files(files, "reception", options)
    reference = whole(files)
    assert built.stats.mode == "incremental" and built.rule_count == reference.rule_count == 32
    assert built.expanded == reference.expanded
    for example in json.loads(files["examples.json"]):
        assert fire(built, example["facts"]) == fire(reference, example["facts"]), example["name"]


# --------------------------------------------------------------------------- big sets


def test_a_thousand_rule_set_builds_edits_and_fires_as_expected(options):
    files = growth_rules.drl_files(1000)
    compiled = compiler.compile_files(files, "growth", options)
    assert compiled.rule_count == 1000 and compiled.stats.units_compiled > 1
    assert compiled.stats.rules_built == 1000 and compiled.stats.rules_compiled == 0  # all plain shapes
    for k in range(6):
        facts = growth_rules.sample_facts(k)
        got = {}
        for rule, _, _ in fire(compiled, facts)["actions"]:
            got[rule] = got.get(rule, 0) + 1
        assert got == growth_rules.expected_firings(1000, facts)
    variants = {517: 1}
    edited = compiler.compile_files(growth_rules.drl_files(1000, variants), "growth", options)
    assert edited.stats.rules_built == 1 and edited.stats.units_reused > 1
    for k in range(6):
        facts = growth_rules.sample_facts(k)
        fired = [rule for rule, _, _ in fire(edited, facts)["actions"]]
        assert sorted(set(fired)) == sorted(growth_rules.expected_firings(1000, facts, variants))


def test_a_bad_rule_among_a_thousand_is_located_and_nothing_serving_changes(tmp_path, options):
    from gateway.config import Settings
    from gateway.engine import Engine

    engine = Engine(Settings(data_dir=str(tmp_path / "data"), engine={
        "rules_dir": str(tmp_path / "rules"), "compile_cache_dir": options.cache_dir}))
    files = growth_rules.drl_files(1000)
    engine.deploy("growth", files)
    served = engine.fire("growth", growth_rules.sample_facts(2)).to_dict()["actions"]
    broken = dict(files)
    text = broken["rules_001.drl"]
    at = text.index('rule "r00700')
    broken["rules_001.drl"] = text[:at] + text[at:].replace("actions.say(", "actions.sya(", 1)
    with pytest.raises(CompileFailed) as failed:
        engine.deploy("growth", broken)
    error = failed.value.errors[0]
    line = broken["rules_001.drl"][:broken["rules_001.drl"].index("actions.sya(")].count("\n") + 1
    assert (error.file, error.line) == ("rules_001.drl", line) and error.column > 0
    assert engine.current("growth").info.version == 1
    assert engine.fire("growth", growth_rules.sample_facts(2)).to_dict()["actions"] == served


def test_plain_rules_fire_as_compiled_ones_and_share_their_nodes(options):
    """The growth shapes built at run time against the same rules compiled to Java, and a set that
    mixes both for the same constraints (a compiled rule's then-part is not plain): equal constraints
    must be one node, or Drools' alpha hashing keeps only one of them and a rule never fires."""
    files = growth_rules.drl_files(300)
    plain = compiler.compile_files(files, "plain", options)
    compiled = compiler.compile_files(files, "compiled", CompileOptions(incremental=True, disk_cache=False,
                                                                        plain_rules=False))
    assert plain.stats.rules_built == 300 and compiled.stats.rules_built == 0
    mixed_files = dict(files)
    mixed_files["mixed.drl"] = f"package {growth_rules.PACKAGE};\n\n" + "\n".join(
        growth_rules.rule_drl(i).replace(f'rule "{growth_rules.rule_name(i)}"', f'rule "copy {i}"')
        .replace(f'actions.say("bot", "{growth_rules.rule_name(i)}");', f'actions.say("bot", "copy " + ({i}));')
        for i in range(0, 300, 3))
    mixed = compiler.compile_files(mixed_files, "mixed", options)
    assert mixed.stats.rules_compiled == 100 and mixed.stats.rules_built == 300  # a new file: new package header
    reference = whole(mixed_files)
    for k in range(40):
        facts = growth_rules.sample_facts(k)
        assert fire(plain, facts) == fire(compiled, facts), k
        assert fire(mixed, facts) == fire(reference, facts), k


def test_rules_the_plain_builder_refuses_go_to_the_compiler(options):
    rules = HEADER + textwrap.dedent("""\
        rule "unknown method"
        when
            Customer(age > 3)
        then
            actions.shout("bot", "hi");
        end

        rule "wrong literal"
        when
            Customer(age > 3.5)
        then
            actions.say("bot", "wrong literal");
        end

        rule "plain"
        when
            Customer(age > 3)
        then
            actions.say("bot", "plain");
        end
        """)
    files = {"types.drl": TYPES.format(extra=""), "a.drl": rules.replace('actions.shout("bot", "hi");', "")}
    built = compiler.compile_files(files, "refused", options)
    assert built.stats.rules_built == 2 and built.stats.rules_compiled == 1  # "wrong literal": int vs 3.5
    facts = [{"type": "Customer", "id": "c1", "age": 4, "tier": "gold"}]
    assert fire(built, facts) == fire(whole(files), facts)
    with pytest.raises(CompileFailed) as failed:
        compiler.compile_files({**files, "a.drl": rules}, "refused", options)
    error = failed.value.errors[0]
    assert (error.file, error.line) == ("a.drl", 7) and error.column > 0
    # a variable bound inside an accumulate is not visible after it: an error, never a plain rule
    scoped = HEADER + textwrap.dedent("""\
        rule "scoped"
        when
            $c: Customer()
            accumulate($o: Order(customer == $c.id, $a: amount); $t: sum($a); $t > 1.0)
            Customer(id == $o.customer)
        then
            actions.say("bot", "scoped");
        end
        """)
    with pytest.raises(CompileFailed) as failed:
        compiler.compile_files({**files, "a.drl": scoped}, "refused", options)
    assert (failed.value.errors[0].file, failed.value.errors[0].line) == ("a.drl", 7)


# --------------------------------------------------------------------------- caches and artifacts


def test_the_disk_cache_serves_another_process_without_compiling(options, tmp_path):
    files = growth_rules.drl_files(120)
    compiler.compile_files(files, "shared", options)
    (tmp_path / "files.json").write_text(json.dumps(files))
    report = _run_python(f"""
        import json
        from gateway.engine import compiler
        files = json.load(open({str(tmp_path / "files.json")!r}))
        c = compiler.compile_files(files, "shared", compiler.CompileOptions(cache_dir={options.cache_dir!r}))
        edited = dict(files, **{{"rules_000.drl": files["rules_000.drl"].replace("r00007", "r00007 edited")}})
        e = compiler.compile_files(edited, "shared", compiler.CompileOptions(cache_dir={options.cache_dir!r}))
        print("RESULT", json.dumps([c.stats.to_dict(), e.stats.to_dict(), c.rule_count]))
    """)
    same, edited, rules = report
    assert same["mode"] == "plan" and (same["rules_compiled"] + same["rules_built"]) == 0 and rules == 120
    assert edited["mode"] == "incremental" and (edited["rules_compiled"] + edited["rules_built"]) == 1


def test_another_host_assembles_from_the_shared_units_without_compiling(options, tmp_path, store):
    """Units and plans go to the Information State too: a gateway on another host (its own empty
    disk cache, a fresh memory) assembles the set from them, and a one-rule edit there compiles
    one rule. A real MongoDB-protocol server."""
    from gateway.store.unit_store import SharedUnitStore

    files = growth_rules.drl_files(120)
    facts = growth_rules.sample_facts(2)
    incremental.share_units(SharedUnitStore(store.db))
    try:
        first = compiler.compile_files(files, "hosts", options)
        assert store.db["rule_units"].count_documents({}) == first.stats.units_compiled
        incremental.reset()  # another host: nothing in memory, and another disk
        other = CompileOptions(cache_dir=str(tmp_path / "other-host"))
        there = compiler.compile_files(files, "hosts", other)
        assert there.stats.mode == "plan" and rebuilt_rules(there.stats) == 0 and there.rule_count == 120
        fire = lambda c: json.loads(str(c.runner.fire(encode_facts(facts, 100), 1000, False, True)))["actions"]  # noqa: E731
        assert fire(there) == fire(first)
        edited = dict(files, **{"rules_000.drl": files["rules_000.drl"].replace("r00007", "r00007 edited")})
        again = compiler.compile_files(edited, "hosts", other)
        assert again.stats.mode == "incremental" and rebuilt_rules(again.stats) == 1
        assert list((tmp_path / "other-host").rglob("units/*.zip"))  # kept on that host's disk too
    finally:
        incremental.share_units(None)


def test_the_shared_tier_failing_never_fails_a_build(options):
    """The database away: every shared lookup and write fails, the build compiles locally."""
    from gateway.store.unit_store import SharedUnitStore

    class DownDb(dict):
        def __missing__(self, name):
            from pymongo.errors import ServerSelectionTimeoutError

            class Coll:
                def __getattr__(self, _):
                    def fail(*a, **k):
                        raise ServerSelectionTimeoutError("no server")
                    return fail
            return Coll()

    incremental.share_units(SharedUnitStore(DownDb()))
    try:
        built = compiler.compile_files(growth_rules.drl_files(20), "down", options)
        assert built.rule_count == 20 and rebuilt_rules(built.stats) == 20
    finally:
        incremental.share_units(None)


def test_export_and_load_a_compiled_set_in_another_process(options, tmp_path):
    files = growth_rules.drl_files(150)
    compiled = compiler.compile_files(files, "moved", options)
    data = export_compiled(compiled, options)
    (tmp_path / "set.bin").write_bytes(data)
    (tmp_path / "files.json").write_text(json.dumps(files))
    facts = growth_rules.sample_facts(4)
    report = _run_python(f"""
        import json
        from gateway.engine import compiler
        from gateway.engine.artifacts import load_compiled
        from gateway.engine.results import encode_facts
        files = json.load(open({str(tmp_path / "files.json")!r}))
        options = compiler.CompileOptions(cache_dir={str(tmp_path / "other-cache")!r})
        c = load_compiled(open({str(tmp_path / "set.bin")!r}, "rb").read(), files, options)
        answer = json.loads(str(c.runner.fire(encode_facts({facts!r}, 100), 1000, False, True)))
        print("RESULT", json.dumps([c.stats.to_dict(), c.rule_count, answer["actions"]]))
    """)
    stats, rules, actions = report
    assert stats["mode"] == "loaded" and (stats["rules_compiled"] + stats["rules_built"]) == 0 and rules == 150
    answer = json.loads(str(compiled.runner.fire(encode_facts(facts, 100), 1000, False, True)))
    assert actions == answer["actions"]


def test_load_compiled_refuses_other_files_and_other_environments(options):
    files = growth_rules.drl_files(20)
    data = export_compiled(compiler.compile_files(files, "x", options), options)
    with pytest.raises(IncompatibleArtifact, match="other files"):
        load_compiled(data, dict(files, **{"types.drl": files["types.drl"] + "\n"}), options)
    import io
    import zipfile

    buffer = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(data)) as src, zipfile.ZipFile(buffer, "w") as dst:
        for name in src.namelist():
            body = src.read(name)
            if name == "manifest.json":
                manifest = json.loads(body)
                manifest["env"] = "drools-7.0-other"
                body = json.dumps(manifest).encode()
            dst.writestr(name, body)
    with pytest.raises(IncompatibleArtifact, match="compiled for drools-7.0-other"):
        load_compiled(buffer.getvalue(), files, options)
    with pytest.raises(IncompatibleArtifact, match="not a compiled rule set"):
        load_compiled(b"not a zip", files, options)


def test_an_archived_plain_unit_that_no_longer_builds_is_an_incompatible_archive(options, tmp_path):
    """A plain unit is built again when loaded; if its description no longer builds here (a field
    it names is gone), the archive is refused like one for another environment, not half loaded."""
    import io
    import zipfile

    files = growth_rules.drl_files(20)
    data = export_compiled(compiler.compile_files(files, "x", options), options)
    buffer = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(data)) as src, zipfile.ZipFile(buffer, "w") as dst:
        for name in src.namelist():
            body = src.read(name)
            if name.startswith("units/") and b'"field":"tier"' in body:
                body = body.replace(b'"field":"tier"', b'"field":"rank"')
            dst.writestr(name, body)
    incremental.reset()
    with pytest.raises(IncompatibleArtifact, match="does not load here"):
        load_compiled(buffer.getvalue(), files, CompileOptions(cache_dir=str(tmp_path / "elsewhere")))


def test_a_unit_evicted_from_the_disk_cache_is_compiled_again(options, tmp_path):
    files = growth_rules.drl_files(40)
    compiler.compile_files(files, "evicted", options)
    incremental.reset()  # a fresh process, as far as memory goes
    for unit in Path(options.cache_dir).rglob("units/*.zip"):
        unit.unlink()
    rebuilt = compiler.compile_files(files, "evicted", options)
    assert rebuilt.stats.mode == "incremental" and rebuilt_rules(rebuilt.stats) == 40


# --------------------------------------------------------------------------- limits, warming


def test_the_compile_time_limit_is_a_resource_error_and_leaves_serving_alone(tmp_path, options):
    from gateway.api.errors import engine_error_response
    from gateway.config import Settings
    from gateway.engine import Engine
    from gateway.base.versions import MemoryCatalog

    settings = {"rules_dir": str(tmp_path / "rules"), "compile_cache_dir": options.cache_dir}
    catalog = MemoryCatalog()  # two processes' engines over one catalog
    engine = Engine(Settings(data_dir=str(tmp_path / "data"), engine=settings), catalog)
    engine.deploy("limited", growth_rules.drl_files(10))
    strict = Engine(Settings(data_dir=str(tmp_path / "data"), engine={**settings, "compile_timeout_s": 0.001}), catalog)
    strict.load()
    with pytest.raises(CompileResourceError) as error:
        strict.deploy("limited", growth_rules.drl_files(300))
    assert error.value.reason == "time" and "PRINTEPS_COMPILE_TIMEOUT" in error.value.setting
    assert engine_error_response(error.value)[0] == 503
    assert strict.current("limited").info.version == 1
    assert engine.fire("limited", growth_rules.sample_facts(0)).version == 1


# The parallel collector (a documented `jvm.extra_options` choice) with a strict overhead limit gives
# up once five full collections in a row free little: the default serial collector, which has no such
# limit, thrashed ~170 full collections (23.7 CPU-s) before the same OutOfMemoryError, this 12.7.
OUT_OF_HEAP_JVM = ["-XX:+UseParallelGC", "-XX:ParallelGCThreads=1", "-XX:+UseGCOverheadLimit",
                   "-XX:GCTimeLimit=10", "-XX:GCHeapFreeLimit=50"]


@pytest.mark.slow  # a resource fault: a 32 MB JVM collects until it gives up (~11 s quiet)
def test_running_out_of_heap_while_compiling_is_a_resource_error(tmp_path):
    """A JVM of 32 MB cannot compile 1,000 rules in one piece: the answer names the heap setting."""
    report = _run_python("""
        import json, sys
        sys.path.insert(0, %r)
        import growth_rules
        from gateway.base import jvm
        from gateway.config import JvmSettings
        jvm.start(JvmSettings(max_heap="32m", extra_options=%r))
        from gateway.engine import compiler
        from gateway.engine.errors import CompileResourceError
        try:
            compiler.compile_files(growth_rules.drl_files(1000), "oom", compiler.CompileOptions(incremental=False, disk_cache=False))
            print("RESULT", json.dumps("compiled"))
        except CompileResourceError as exc:
            print("RESULT", json.dumps(exc.to_dict()))
    """ % (str(ROOT / "bench" / "peers"), OUT_OF_HEAP_JVM))
    assert report["reason"] == "memory" and "PRINTEPS_JVM_HEAP" in report["setting"]
    assert "file" not in report  # never blamed on a rule file


def test_a_build_out_of_memory_is_not_blamed_on_the_rules_by_what_jpype_says_next():
    """Out of memory, JPype may answer a JVM call with its own "Fatal error occurred" instead of the
    Java error (1 build in 6 of the test above): the build call itself, or the cleanup after it."""
    assert says_out_of_memory("Fatal error occurred") and not says_out_of_memory("mismatched input")

    class Repository:
        def removeKieModule(self, release: object) -> None:
            raise RuntimeError("Fatal error occurred")

    class Services:
        def getRepository(self) -> Repository:
            return Repository()

    build._forget_module(Services(), "release")  # the error being raised is kept, not replaced


def test_progress_is_reported_by_stage(options):
    seen = []
    compiler.compile_files(growth_rules.drl_files(80), "progress", options, lambda d, t, s: seen.append((s, d, t)))
    stages = list(dict.fromkeys(s for s, _, _ in seen))
    assert stages == ["parse", "compile", "load", "assemble"]
    compile_steps = [(d, t) for s, d, t in seen if s == "compile"]
    assert compile_steps[-1] == (80, 80) and all(d <= t for d, t in compile_steps)


def test_warming_fires_the_examples_once(options):
    files = dict(growth_rules.drl_files(30), **{"examples.json": json.dumps(
        [{"name": "one", "facts": growth_rules.sample_facts(1)}])})
    compiled = compiler.compile_files(files, "warm", options)
    stats = warm(compiled, files, budget_s=0.01, max_fires=50)
    assert stats.fires >= 3 and compiled.warmed
    assert warm(compiled, files).fires == 0
    assert {f["type"] for f in plain_facts(compiled.types)} == {"Customer", "Order", "Product"}


def test_warming_samples_made_of_the_rules_literals_reach_their_joins(options):
    """A fresh set with no examples and no traffic: the literal samples pass the rules' alpha
    tests, so the join and its consequence are warmed too (plain values alone reach neither)."""
    rules = HEADER + ('rule "vip order" when $c : Customer( tier == "vip", age >= 30 ) '
                      'Order( customer == $c.id, amount > 750.0 ) then actions.say("bot", "vip"); end\n')
    files = {"types.drl": TYPES.format(extra=""), "rules.drl": rules}
    compiled = compiler.compile_files(files, "literals", options)
    samples = literal_facts(compiled.types, files)
    assert samples and all({f["type"] for f in facts} == {"Customer", "Order"} for facts in samples)
    assert any(fire(compiled, facts)["fired"] == ["vip order"] for facts in samples)
    assert fire(compiled, plain_facts(compiled.types))["fired"] == []


# --------------------------------------------------------------------------- helpers


def _run_python(code: str) -> object:
    """Runs ``code`` in a fresh Python process (its own JVM) and returns what it printed after RESULT."""
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          cwd=ROOT, timeout=600, env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line.removeprefix("RESULT "))
    raise AssertionError(f"no result (exit {proc.returncode}):\n{proc.stdout[-2000:]}\n{proc.stderr[-4000:]}")


def test_rules_without_a_package_and_rule_inheritance_build(options):
    plain = {"a.drl": 'declare Thing id: String end\nrule "one" when Thing() then System.out.print(""); end\n',
             "b.drl": 'rule "two" when $t: Thing(id == "x") then System.out.print(""); end\n'}
    built = compiler.compile_files(plain, "nopkg", options)
    assert built.stats.mode == "incremental" and built.rule_count == 2
    assert fire(built, [{"type": "Thing", "id": "x"}])["fired"] == fire(whole(plain), [{"type": "Thing", "id": "x"}])["fired"]
    inherited = {"r.drl": HEADER.replace("\n\n", "\ndeclare Thing id: String end\n")
                 + 'rule "base" when $t: Thing() then end\nrule "child" extends "base" when Thing(id == "x") then end\n'}
    built = compiler.compile_files(inherited, "extends", options)
    assert built.stats.mode == "whole" and built.rule_count == 2  # one unit: a child needs its parent


def test_warming_the_builder_compiles_a_fresh_set_each_round(options):
    before = compiler._cache.copy()
    compiler.warm_builder(rounds=2)
    assert compiler._cache == before  # nothing kept for serving


@pytest.mark.parametrize("seed", [3, 4])
def test_reused_sessions_answer_as_fresh_ones(options, seed):
    """The Runner empties a session after a request and gives it to the next: over a varied
    request stream (rules that modify facts, joins, accumulates, queries, salience) every answer
    equals that of a session of its own. Without agenda groups the emptied session is not fired
    before it is given back (its deletions reach the agenda with the next request's insertions)."""
    from gateway.base import jvm

    rule_set = RandomSet(seed, queries=False)  # a rule opening with a query call disables reuse (below)
    compiled = compiler.compile_files(rule_set.files(), "reuse", options)
    assert compiled.runner.reusesSessions() and not compiled.runner.settlesDeletions()
    requests = rule_set.facts() * 3
    random.Random(seed).shuffle(requests)
    runner_class = jvm.helper_class("Runner")
    for facts in requests:
        fresh = runner_class(compiled.kbase)  # a new Runner: its first session is a new one
        reused = json.loads(str(compiled.runner.fire(encode_facts(facts, 100), 10_000, True, True)))
        alone = json.loads(str(fresh.fire(encode_facts(facts, 100), 10_000, True, True)))
        assert reused == alone
    with_query = RandomSet(seed)
    with_query.rules["a.drl"].append(("q", 'rule "q" when ?bigSpenders(1.0;) then actions.say("b", "q"); end\n'))
    assert not compiler.compile_files(with_query.files(), "reuse", options).runner.reusesSessions()


TWIN_JOINS = """package org.printeps.inc;
import org.printeps.gateway.Actions;
global Actions actions;

declare Applicant
    id: String
    segment: String
end

declare Loan
    id: String
    applicant: String
    amount: double
end
"""
# Two rules of each shape, alike but for their names: Drools shares their join or exists node.
TWIN_JOINS += "".join(f"""
rule "{name}" when
    $a : Applicant( segment == "s2", $id : id )
    {joined} Loan( applicant == $id, amount > 100.0 )
then
    actions.say("bot", "{name}");
end
""" for name, joined in (("first", "$l :"), ("second", "$l :"), ("exists", "exists"), ("exists twin", "exists")))


def test_a_rule_rebuilt_alone_shares_its_nodes_as_in_one_build(options):
    """A one-rule edit builds that rule in a unit of its own. Drools shares a join or ``exists``
    node between rules whose conditions are alike only when their declarations compare equal, and
    the order a shared node hands its matches to the rules after it differs from that of separate
    nodes: the rebuilt rule must share as it does in a build of the whole set, or its matches
    fire in another order than KIE Server's (the plain builder's field readers compared by
    identity, so two units never shared such a node)."""
    compiler.compile_files({"rules.drl": TWIN_JOINS}, "twins", options)
    edited = {"rules.drl": TWIN_JOINS.replace('actions.say("bot", "first");', 'actions.say("bot", "first!");')
              .replace('actions.say("bot", "exists");', 'actions.say("bot", "exists!");')}
    built = compiler.compile_files(edited, "twins", options)
    assert rebuilt_rules(built.stats) == 2 and built.stats.rules_built == 2  # plain rules, each alone
    reference = whole(edited)
    facts = [{"type": "Applicant", "id": f"a{k}", "segment": "s2"} for k in range(3)]
    facts += [{"type": "Loan", "id": f"l{k}", "applicant": f"a{k % 3}", "amount": 150.0 + k} for k in range(7)]
    answers = [json.loads(str(c.runner.fire(encode_facts(facts, 100), 10_000, False, True))) for c in (built, reference)]
    fired = [[(f["rule"], [x["id"] for x in f["facts"] if isinstance(x, dict)]) for f in a["fired"]] for a in answers]
    assert len(fired[0]) == 2 * 7 + 2 * 3
    assert fired[0] == fired[1]
