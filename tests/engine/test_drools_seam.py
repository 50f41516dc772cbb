"""The Drools seam's contract: every assumption ``DroolsInternals.java`` (and
``DroolsLinkOrder.java``) makes about Drools' implementation, checked against the Drools on the
classpath, pinned to the version it was written for. A Drools upgrade fails here, naming the seam method to adapt, instead of silently (a changed
constraint-id formula leaves a plain rule that never fires, with no error anywhere).

Also: no other Java helper, and no Python module, reaches into Drools' implementation.
Real JVM, real Drools builds; see docs/architecture.md, "The Drools seam".
"""

from __future__ import annotations

import json
import re
import uuid
from pathlib import Path

import jpype
import pytest

from gateway.base import jvm
from gateway.engine import compiler, incremental
from gateway.engine.compiler import CompileOptions
from gateway.engine.results import encode_facts

ROOT = Path(__file__).resolve().parents[2]
JAVA = ROOT / "java" / "src" / "org" / "printeps" / "gateway"
PACKAGE = "org.printeps.seam"
#: The seam's files: every use of Drools' implementation, and nothing else, is in them.
SEAM = {"DroolsInternals.java", "DroolsLinkOrder.java"}

TYPES = f"""package {PACKAGE};
import org.printeps.gateway.Actions;
global Actions actions;

declare Customer
    id: String
    tier: String
    age: int
    score: double
    vip: boolean
end

declare Order
    id: String
    customer: String
    amount: double
end

query olderThan(int $min)
    Customer(age > $min)
end
"""

#: Every constraint shape PlainRules builds: text, number and boolean equality, inequality,
#: ordering on int and double, a join on a bound fact's field, and a sum accumulate.
WHEN = """    $c: Customer(tier == "gold", tier != "lead", age > 30, age >= 31, age < 90, age <= 89, score == 2.5,
                 score > 1.0, vip == true)
    $o: Order(customer == $c.id, amount >= 10.0)
    accumulate(Order(customer == $c.id, $a: amount); $t: sum($a); $t > 100.0)"""

PLAIN = f"""package {PACKAGE};

rule "plain"
when
{WHEN}
then
    actions.say("bot", "plain");
end
"""

#: The same conditions; a then-part that is not of a plain shape makes the builder compile it.
COMPILED = f"""package {PACKAGE};

rule "compiled"
when
{WHEN}
then
    actions.say("bot", "compiled " + (1));
end
"""

#: Rules and attributes the engine reads through the seam (calendar, session reuse).
MODULE = TYPES + f"""
rule "from facts"
when
    Customer(age > 1)
    Order(amount > 1.0)
then
end

rule "from the initial fact"
when
    not Customer()
then
end

rule "in a group"
    agenda-group "g"
when
    Customer()
then
end

rule "locked"
    agenda-group "g"
    lock-on-active
    salience 10
when
    Customer(tier == "locked")
then
end

rule "on a calendar"
    date-effective "1-Jan-2020"
when
    Customer()
then
end

rule "no loop"
    no-loop
when
    Customer(tier == "loop")
    $o: Order(id == "shared", amount >= 0.0)
then
    modify($o) {{ setAmount($o.getAmount() + 1.0) }};
end
"""


def broken(method: str, what: str) -> str:
    """The failure message: which seam method's assumption no longer holds, on which Drools."""
    seam = jvm.helper_class("DroolsInternals")
    return (f"Drools seam broken: DroolsInternals.{method} assumes {what} "
            f"(checked on Drools {seam.CHECKED_VERSION}, running {seam.droolsVersion()}); "
            "see docs/architecture.md, 'The Drools seam'")


@pytest.fixture(scope="module")
def seam():
    return jvm.helper_class("DroolsInternals")


@pytest.fixture()
def options(tmp_path):
    incremental.reset()
    yield CompileOptions(cache_dir=str(tmp_path / "units"))
    incremental.reset()


def fire(compiled, facts) -> list[str]:
    answer = json.loads(str(compiled.runner.fire(encode_facts(facts, 10_000), 10_000, False, True)))
    assert answer["ok"], answer
    return sorted(f["rule"] for f in answer["fired"])


def facts(**customer) -> list[dict]:
    c = {"type": "Customer", "id": "c1", "tier": "gold", "age": 40, "score": 2.5, "vip": True, **customer}
    return [c, {"type": "Order", "id": "o1", "customer": "c1", "amount": 60.0},
            {"type": "Order", "id": "o2", "customer": "c1", "amount": 50.0}]


def build_module(source: str):
    """A KieModule built with the executable model, as compiler.build_unit builds one."""
    java_ks = jvm.jclass("org.kie.api.KieServices").Factory.get()
    kfs = java_ks.newKieFileSystem()
    release = java_ks.newReleaseId("org.printeps.seamtest", f"m{uuid.uuid4().hex[:12]}", "1.0.0")
    kfs.generateAndWritePomXML(release)
    kfs.write("src/main/resources/org/printeps/seam/module.drl", source)
    builder = java_ks.newKieBuilder(kfs)
    builder.buildAll(jvm.helper_class("DroolsInternals").executableModelProject())
    errors = [str(m) for m in builder.getResults().getMessages(jvm.jclass("org.kie.api.builder.Message$Level").ERROR)]
    assert not errors, errors
    module = builder.getKieModule()
    java_ks.getRepository().removeKieModule(release)
    return module


@pytest.fixture(scope="module")
def module_kbase():
    """MODULE built as the engine builds units: module -> class bytes -> loader -> models -> KieBase."""
    seam = jvm.helper_class("DroolsInternals")
    units = jvm.helper_class("Units")
    module = build_module(MODULE)
    names = [str(n) for n in seam.modelClassNames(module)]
    assert names, broken("modelClassNames", "a built module lists its Rules classes in a '/drools-model' file")
    classes = units.classesOf(module)
    assert all(classes.containsKey(n) for n in names), broken(
        "moduleFileNames/moduleFile", "a built KieModule is an InternalKieModule holding the generated .class files")
    loader = units.loader(None, classes)
    models = units.models(loader, names)
    java_ks = jvm.jclass("org.kie.api.KieServices").Factory.get()
    kbase = seam.kieBaseFromModels(models, java_ks.newKieBaseConfiguration())
    return kbase, loader, classes


# --------------------------------------------------------------------------- the version


def test_the_drools_on_the_classpath_is_the_version_the_seam_was_checked_against(seam):
    assert str(seam.CHECKED_VERSION) == "8.31.1.Final"
    assert str(seam.droolsVersion()) == str(seam.CHECKED_VERSION), broken(
        "droolsVersion", "the Drools jars are 8.31.1.Final: re-check every assumption of the seam, then move CHECKED_VERSION")
    drools_jars = [Path(j).name for j in jvm.drools_jars() if Path(j).name.startswith(("drools-", "kie-"))]
    assert drools_jars and all("-8.31.1.Final" in name for name in drools_jars), drools_jars


# --------------------------------------------------------------------------- plain and compiled rules


def test_plain_and_compiled_rules_carry_the_same_constraint_ids_and_share_their_nodes(seam, options):
    """One set with the same conditions built at run time (PlainRules) and compiled to Java: their
    constraint ids must be equal, every constraint one alpha node, and both rules must fire."""
    files = {"types.drl": TYPES, "plain.drl": PLAIN, "compiled.drl": COMPILED}
    mixed = compiler.compile_files(files, "seam", options)
    assert (mixed.stats.rules_built, mixed.stats.rules_compiled) == (1, 1), (
        "the plain builder no longer takes the plain rule: this test would not compare anything", mixed.stats)
    whole = compiler.compile_files(files, "seam-whole", CompileOptions(incremental=False, disk_cache=False))

    plain_ids = [str(i) for i in seam.constraintIds(mixed.kbase, PACKAGE, "plain")]
    compiled_ids = [str(i) for i in seam.constraintIds(mixed.kbase, PACKAGE, "compiled")]
    generated_ids = [str(i) for i in seam.constraintIds(whole.kbase, PACKAGE, "plain")]
    assert len(plain_ids) >= 11 and all(i.startswith("GENERATED_") for i in generated_ids), (plain_ids, generated_ids)
    assert plain_ids == generated_ids == compiled_ids, broken(
        "constraintExprId", "the code generator's ids are 'GENERATED_' + md5(pattern class + EvaluationUtil expression)")

    alpha = [str(i) for i in seam.alphaNodeConstraintIds(mixed.kbase) if str(i).startswith("GENERATED_")]
    assert len(alpha) == 10 and set(alpha) < set(plain_ids), broken(  # 9 on Customer, 1 on Order: one node each
        "constraintExprId", f"equal ids make one alpha node (alpha nodes: {alpha})")

    assert fire(mixed, facts()) == ["compiled", "compiled", "plain", "plain"], broken(  # once per order
        "constraintExprId/domainClassMetadata/sum", "a plain rule fires beside its compiled twin")
    assert fire(mixed, facts()) == fire(whole, facts())
    for miss in ({"tier": "lead"}, {"age": 30}, {"score": 2.0}, {"vip": False}):
        assert fire(mixed, facts(**miss)) == [] == fire(whole, facts(**miss)), miss
    small = facts()[:2]  # one order of 60: the sum is not over 100
    assert fire(mixed, small) == [] == fire(whole, small)


def test_property_indexes_mirror_the_generated_domain_classes_metadata(seam, module_kbase):
    """Alpha hashing and property reactivity key on property indexes: the mirror must number every
    property of every class as the generated DomainClassesMetadata does."""
    _, loader, classes = module_kbase
    meta_type = jvm.jclass("org.drools.model.DomainClassMetadata")
    generated = [n for n in (str(k) for k in classes.keySet()) if "DomainClassesMetadata" in n]
    assert generated, broken("domainClassMetadata", "the generator writes a DomainClassesMetadata class per module")
    checked = []
    for name in generated:
        cls = jvm.jclass("java.lang.Class").forName(name, True, loader)
        for field in cls.getFields():
            if not meta_type.class_.isAssignableFrom(field.getType()):
                continue
            meta = field.get(None)
            domain = meta.getDomainClass()
            mirror = seam.domainClassMetadata(domain)
            assert mirror.getPropertiesSize() == meta.getPropertiesSize(), broken(
                "domainClassMetadata", f"{domain.getName()} has the properties ClassUtil lists")
            numbered = {str(f.getName()): index_of(meta, str(f.getName())) for f in domain.getDeclaredFields()}
            assert {p: index_of(mirror, p) for p in numbered} == numbered, broken(
                "domainClassMetadata", f"the properties of {domain.getName()} are numbered in ClassUtil's order")
            checked.append(str(domain.getSimpleName()))
    assert {"Customer", "Order"} <= set(checked), checked


def index_of(metadata, prop: str) -> int | None:
    """A property's index, None for a field that is no property (e.g. one without a getter)."""
    try:
        return int(metadata.getPropertyIndex(prop))
    except Exception:  # the RuntimeException both raise for an unknown property
        return None


# --------------------------------------------------------------------------- rules and queries


def test_rule_and_query_definitions_are_read_as_the_engine_expects(seam, module_kbase):
    kbase, _, _ = module_kbase
    rule = {name: kbase.getRule(PACKAGE, name) for name in
            ("from facts", "from the initial fact", "in a group", "on a calendar")}
    assert [bool(seam.hasCalendarAttributes(r)) for r in rule.values()] == [False, False, False, True], broken(
        "hasCalendarAttributes", "rules are RuleImpls with date-effective/date-expires")
    assert [bool(seam.matchesOnlyFromFacts(r)) for r in rule.values()] == [True, False, True, True], broken(
        "matchesOnlyFromFacts", "rules are RuleImpls whose LHS opens with a Pattern (not/exists start from InitialFact)")
    assert [bool(seam.movesFocus(r)) for r in rule.values()] == [False, False, True, False], broken(
        "movesFocus", "rules are RuleImpls whose agenda group is MAIN unless declared")
    query = next(q for q in kbase.getKiePackage(PACKAGE).getQueries() if str(q.getName()) == "olderThan")
    assert [str(t.getName()) for t in seam.queryParameterTypes(query)] == ["int"], broken(
        "queryParameterTypes", "queries are QueryImpls whose parameters are typed Declarations")
    assert bool(seam.matchesOnlyFromFacts(query))


def test_the_memories_a_fact_enters_untested(seam, options):
    """What decides whether a set gets a request-join network (Runner.requestJoinsPay): how many
    join, not, exists and accumulate nodes a type's node feeds without an alpha test (here Order's:
    the join and the not, not the join behind ``amount > 5.0``; the auto-focus rule's pattern has
    no join)."""
    drl = TYPES + """
rule "focused"
    auto-focus true
when
    Customer()
then
end

rule "joined"
when
    $c: Customer(tier == "a")
    Order(customer == $c.id)
then
end

rule "not joined"
when
    $c: Customer(tier == "a")
    not Order(customer == $c.id)
then
end

rule "tested"
when
    $c: Customer(tier == "b")
    Order(customer == $c.id, amount > 5.0)
then
end
"""
    kbase = compiler.compile_files({"r.drl": drl}, "fanout", options).kbase
    assert int(seam.untestedRightInputs(kbase)) == 2, broken(
        "untestedRightInputs", "a RuleBase's Rete lists its ObjectTypeNodes, whose sinks include the BetaNodes they feed")


#: Auto-focus rules whose nodes sit in every place a type's node propagates to, declared in
#: another order than Drools links them: under a hashed alpha node ("nested": a child of "hashed"'s
#: node, listed among its range-indexable sinks), hashed (three tier tests), range-indexed (nine
#: age tests: Drools' default AlphaRangeIndexThresholdOption), hashable (one vip test) and a left
#: input without a test ("other"). The joins give tier and age their other tests.
LINK_ORDER = TYPES + "".join(f"""
rule "{name}"
    auto-focus true
    agenda-group "g-{name}"
when
    Customer( {test} )
then
end
""" for name, test in [("other", ""), ("hashable", "vip == true"), ("range", "age > 18"), ("hashed", 'tier == "gold"'),
                        ("nested", 'tier == "gold", score > 1.0')]) + "".join(f"""
rule "join {k}"
when
    $o: Order()
    Customer( {test}, id == $o.customer )
then
end
""" for k, test in enumerate(['tier == "silver"', 'tier == "bronze"'] + [f"age > {20 + 10 * k}" for k in range(8)]))


def test_the_link_order_of_auto_focus_rules_is_the_order_a_type_node_propagates_in(seam, options):
    """DroolsLinkOrder numbers the nodes that link rules in the order a type's node propagates a
    fact (hashed, range-indexed, hashable, range-indexable, others; an alpha node's children
    likewise), and a fire of a request-join network puts the eager rules one fact links in that
    order. Here, in the rule base's own session, the order it predicts must be Drools' own: a
    session whose fire reorders by it ends with the same eager list as one that does not. These
    rules have one pattern: the walk finds them as alpha terminal nodes in that order too
    (sameFocusOrder compares that order in the rule base and in a request-join network)."""
    kbase = compiler.compile_files({"r.drl": LINK_ORDER}, "linkorder", options).kbase
    link_order = jvm.helper_class("DroolsLinkOrder")
    customer_type = kbase.getFactType(PACKAGE, "Customer")

    def customer():
        c = customer_type.newInstance()
        for field, value in {"id": "c1", "tier": "gold", "age": jpype.JInt(50), "score": 2.0, "vip": True}.items():
            customer_type.set(c, field, value)
        return c

    drools, predicted = kbase.newKieSession(), kbase.newKieSession()
    try:
        drools.insert(customer())
        order = [str(n) for n in link_order.eagerRules(drools)]
        assert order == ["nested", "hashed", "range", "hashable", "other"], broken(
            "DroolsLinkOrder", "a type node propagates to hashed, range-indexed, hashable, range-indexable, "
            f"then other sinks, each alpha node's children likewise; eager rules are listed as linked: {order}")
        assert [str(n) for n in link_order.focusOrder(kbase)] == order, broken(
            "DroolsLinkOrder.sameFocusOrder", "an auto-focus rule of one pattern is an AlphaTerminalNode, reached in "
            "the walk's order (its match, and its group's focus, come when a fact reaches it)")
        fire = link_order.of(kbase).begin(predicted)
        fire.inserted(predicted.insert(customer()))
        assert [str(n) for n in link_order.eagerRules(predicted)] == order, broken(
            "DroolsLinkOrder.of", "the walk of the alpha network visits nodes in propagation order")
    finally:
        drools.dispose()
        predicted.dispose()


# --------------------------------------------------------------------------- sessions: handles and agenda


def test_fact_handles_and_the_agenda_focus(seam, module_kbase):
    kbase, _, _ = module_kbase
    session = kbase.newKieSession()
    try:
        customer_type = kbase.getFactType(PACKAGE, "Customer")
        first, second = customer_type.newInstance(), customer_type.newInstance()
        customer_type.set(first, "id", "c1")
        customer_type.set(second, "id", "c2")
        session.insert(first)
        handle = session.insert(second)
        system = jvm.jclass("java.lang.System")
        parts = str(handle.toExternalForm()).split(":")
        assert parts[0] == "0" and int(parts[1]) == int(seam.handleId(handle)) and int(
            parts[2]) == int(seam.identityHashCode(handle)) == int(system.identityHashCode(second)), broken(
            "handleId/identityHashCode", f"handles are InternalFactHandles whose external form is "
            f"0:id:identityHashCode:... (Handles.resolve parses it): {handle.toExternalForm()}")
        assert seam.objectOf(handle).equals(second) and str(seam.entryPointName(handle)) == "DEFAULT", broken(
            "objectOf/entryPointName", "a handle holds its fact and its entry point's name")
        ids = sorted(int(seam.handleId(h)) for h in session.getFactHandles())
        assert ids == sorted(set(ids)) and int(seam.handleId(handle)) == ids[-1], broken(
            "handleId", "ids grow in insertion order (Runner.inInsertionOrder sorts by them)")
        replacement = customer_type.newInstance()
        customer_type.set(replacement, "id", "c2")
        session.update(handle, replacement)
        assert int(seam.identityHashCode(handle)) == int(system.identityHashCode(replacement)), broken(
            "identityHashCode", "an update that swaps the object changes the handle's identity hash (Handles keeps both)")
        disconnected = {str(k): v for k, v in seam.disconnectedHandle(handle, replacement).items()}
        assert set(disconnected) == {"id", "identityHashCode", "objectHashCode", "recency", "object", "traitType",
                                     "external"}
        assert str(disconnected["external"]) == str(handle.toExternalForm())

        assert str(seam.focusName(session)) == "MAIN", broken("focusName", "getAgenda() is the InternalAgenda")
        session.getAgenda().getAgendaGroup("g").setFocus()  # applied at the next fire
        assert int(session.fireAllRules(1)) == 1  # one of "in a group"'s two matches: the other keeps the focus
        assert str(seam.focusName(session)) == "g", broken("focusName", "getAgenda() is the InternalAgenda")
    finally:
        session.dispose()


def test_the_focus_stack_is_read_whole_bottom_to_top_with_queued_pushes_applied(seam, module_kbase):
    kbase, _, _ = module_kbase
    session = kbase.newKieSession()
    try:
        stack = lambda: [str(g) for g in seam.focusStack(session)]  # noqa: E731
        assert stack() == ["MAIN"], broken("focusStack", "a fresh session's stack is MAIN alone")
        for group in ("a", "g", "MAIN", "g"):
            session.getAgenda().getAgendaGroup(group).setFocus()  # queued: applied by the read
        assert stack() == ["MAIN", "a", "g", "MAIN", "g"], broken(
            "focusStack", "the InternalAgenda's flushPropagations runs queued setFocus pushes and its "
            "StackedAgendaGroupsManager keeps every push in the Deque field focusStack, first = bottom")
        assert str(seam.focusName(session)) == "g"
        session.getAgenda().getAgendaGroup("g").setFocus()
        assert stack()[-2:] == ["MAIN", "g"], broken("focusStack", "a push of the group on top changes nothing")
        assert int(session.fireAllRules()) == 1  # no fact: "from the initial fact" alone, in MAIN; a fire pops the empty groups
        assert stack() == ["MAIN"], broken("focusStack", "a fire pops the empty groups off the stack")
    finally:
        session.dispose()


def test_the_applied_focus_stack_tells_which_group_is_active_for_lock_on_active_rules(seam, module_kbase):
    """What a durable snapshot keeps so that Refraction drops, after a rebuild, the re-activations
    of fired lock-on-active matches that Drools discards while their group is active: which groups
    of the stack Drools has applied are active (a queued push not applied by this read), and which
    group a lock-on-active rule is in; and the Drools behaviour it mirrors: while the group is
    active, a modify the rule listens to does not re-activate its fired match."""
    kbase, _, _ = module_kbase
    session = kbase.newKieSession()
    try:
        applied = lambda: [str(g) for g in seam.appliedFocusStack(session)]  # noqa: E731
        assert str(seam.lockOnActiveGroup(kbase.getRule(PACKAGE, "locked"))) == "g", broken(
            "lockOnActiveGroup", "rules are RuleImpls telling isLockOnActive and getAgendaGroup")
        assert seam.lockOnActiveGroup(kbase.getRule(PACKAGE, "in a group")) is None
        customer_type = kbase.getFactType(PACKAGE, "Customer")
        locked = customer_type.newInstance()
        customer_type.set(locked, "id", "l1")
        customer_type.set(locked, "tier", "locked")
        handle = session.insert(locked)
        session.getAgenda().getAgendaGroup("g").setFocus()
        assert [g.rstrip("*") for g in applied()] == ["MAIN"], broken(
            "appliedFocusStack", "setFocus() only queues its push: the StackedAgendaGroupsManager's focusStack lacks it")
        assert int(session.fireAllRules(1)) == 1  # "locked" (salience 10); "in a group" still waits in "g"
        assert applied() == ["MAIN", "g*"], broken(
            "appliedFocusStack", "a push makes its group active (InternalAgendaGroup.isActive) and the one it covers "
            f"inactive; a fire that stops inside the group leaves it active: {applied()}")
        session.update(handle, locked, "tier")  # a property "locked" listens to, while "g" is active
        fired = []
        listener = jpype.JImplements("org.kie.api.runtime.rule.AgendaFilter")(type("Note", (), {
            "accept": jpype.JOverride(lambda self, match: fired.append(str(match.getRule().getName())) or True)}))()
        session.fireAllRules(listener)
        assert "in a group" in fired and "locked" not in fired, broken(
            "appliedFocusStack", "Drools discards a lock-on-active rule's re-activation while its group is active "
            f"(what Refraction mirrors after a rebuild): {fired}")
        assert applied() == ["MAIN"], broken("appliedFocusStack", "a fire pops the emptied group")
    finally:
        session.dispose()


def _reached(session, rule: str, accept: bool = False) -> list[int]:
    """``lastReachedBy`` of each match of ``rule`` a fire of MAIN meets (each rejected unless ``accept``)."""
    seam = jvm.helper_class("DroolsInternals")
    seen: list[int] = []

    @jpype.JImplements("org.kie.api.runtime.rule.AgendaFilter")
    class Record:
        @jpype.JOverride
        def accept(self, match):
            if str(match.getRule().getName()) != rule:
                return False
            seen.append(int(seam.lastReachedBy(match)))
            return accept

    session.fireAllRules(Record())
    return seen


def test_a_match_keeps_the_number_of_the_last_propagation_that_reached_it(seam, module_kbase):
    """What Refraction tells a match carried into a session (fired before, stays fired) from one
    something re-created or re-activated since by: a modify of a property its patterns do not
    listen to (property reactivity) leaves the match's number, on the left input (the first
    pattern) and on the right one (a join's); a modify they listen to gives it a later one; a
    no-loop rule's own modify marks it -1 (Drools updates it without re-activating it)."""
    kbase, _, _ = module_kbase
    session = kbase.newKieSession()
    try:
        customer_type, order_type = kbase.getFactType(PACKAGE, "Customer"), kbase.getFactType(PACKAGE, "Order")
        customer, order = customer_type.newInstance(), order_type.newInstance()
        customer_type.set(customer, "id", "c1")
        customer_type.set(customer, "age", jpype.JInt(40))
        order_type.set(order, "id", "o1")
        order_type.set(order, "amount", 60.0)
        before = int(seam.propagationMark(session))
        c, o = session.insert(customer), session.insert(order)
        mark = int(seam.propagationMark(session))
        assert before < mark, broken("propagationMark", "the session's propagation numbers grow")
        customer_type.set(customer, "tier", "silver")
        session.update(c, customer, "tier")  # "from facts" listens to age (Customer) and amount (Order) only
        order_type.set(order, "customer", "c9")
        session.update(o, order, "customer")
        inserted = _reached(session, "from facts")
        assert len(inserted) == 1 and before < inserted[0] < mark, broken(
            "lastReachedBy", f"a match keeps its insert's propagation number ({before} < n < {mark}) through modifies "
            f"of properties its patterns do not listen to, left or right: {inserted}")
        for handle, fact, fact_type, prop, value in ((c, customer, customer_type, "age", jpype.JInt(41)), (o, order, order_type, "amount", 61.0)):
            mark = int(seam.propagationMark(session))
            fact_type.set(fact, prop, value)
            session.update(handle, fact, prop)
            reached = _reached(session, "from facts")
            assert len(reached) == 1 and reached[0] > mark, broken(
                "lastReachedBy", f"a modify of {prop}, which the rule listens to, re-activates the match with its own, "
                f"later number (> {mark}): {reached}")
        for name in ("k1", "k2"):
            looping = customer_type.newInstance()
            customer_type.set(looping, "id", name)
            customer_type.set(looping, "tier", "loop")
            session.insert(looping)
        shared = order_type.newInstance()
        order_type.set(shared, "id", "shared")
        session.insert(shared)
        fired = _reached(session, "no loop", accept=True)
        assert len(fired) == 2 and fired[0] > 0 and fired[1] == -1, broken(
            "lastReachedBy", "the first of two matches of a no-loop rule fires and modifies the fact both hold; the "
            f"update reaches the second with its context's terminal node origin the rule's own: -1 ({fired})")
    finally:
        session.dispose()


# --------------------------------------------------------------------------- parsing


def test_drl_and_dsl_parsing_through_the_seam(seam):
    parser = seam.newDrlParser()
    descr = parser.parse(False, MODULE)
    assert descr is not None and parser.getErrors().isEmpty()
    items = json.loads(str(seam.drlItems(descr)))
    assert items["package"] == PACKAGE and items["unit"] is False
    kinds = [(kind, name) for kind, name, *_ in items["items"]]
    assert ("query", "olderThan") in kinds and ("rule", "on a calendar") in kinds and ("type", "Customer") in kinds
    start, end, line = next((s, e, n) for kind, name, s, e, n, _ in items["items"] if name == "from facts")
    assert MODULE[start:end + 1].startswith('rule "from facts"') and MODULE.count("\n", 0, start) + 1 == line, broken(
        "drlItems", "descriptors carry their start/end character offsets and line")

    dsl = seam.newDslMappingFile()
    assert dsl.parseAndLoad(jvm.jclass("java.io.StringReader")("[when]There is a customer=Customer()\n"))
    expander = seam.newDslExpander()
    expander.addDSLMapping(dsl.getMapping())
    expanded = str(expander.expand('rule "r"\nwhen\n    There is a customer\nthen\nend\n'))
    assert "Customer()" in expanded and expander.getErrors().isEmpty()


# --------------------------------------------------------------------------- nothing else reaches in

#: What Java helpers other than the seam may name: the public KIE API and the executable model's
#: rule DSL (the packages its generated code is written against), never its implementation.
ALLOWED = re.compile(r"org\.kie\.api\.|org\.drools\.model\.(?!impl\.|codegen\.|constraints\.|patterns\.|consequences\.)")
REFERENCE = re.compile(r"\b(org\.(?:drools|kie)\.[\w.]+)")


def _code(text: str) -> str:
    """Java text without comments and string literals (a javadoc may name a Drools class)."""
    return re.sub(r'/\*.*?\*/|//[^\n]*|"(?:\\.|[^"\\])*"', " ", text, flags=re.DOTALL)


def test_no_java_helper_but_the_seam_names_a_drools_implementation_class():
    offenders = {}
    for path in sorted(JAVA.glob("*.java")):
        if path.name in SEAM:
            continue
        code = _code(path.read_text(encoding="utf-8"))
        bad = sorted({m for m in REFERENCE.findall(code) if not ALLOWED.match(m)})
        bad += sorted(set(re.findall(r"\bInternal[A-Z]\w*|\bRuleImpl\b|\bQueryImpl\b|\bKieBaseBuilder\b", code)))
        if bad:
            offenders[path.name] = bad
    assert offenders == {}, f"Drools implementation classes outside the seam ({sorted(SEAM)}): {offenders}"


def test_the_scan_catches_an_implementation_class():
    """The scan above must be able to fail: these lines are what it exists to refuse."""
    for line in ("import org.drools.core.common.InternalFactHandle;",
                 "Object o = ((org.drools.core.common.InternalFactHandle) h).getObject();",
                 "import org.drools.model.impl.RuleBuilder;",
                 "import org.kie.internal.builder.conf.LanguageLevelOption;"):
        assert any(not ALLOWED.match(m) for m in REFERENCE.findall(_code(line))), line
    assert not [m for m in REFERENCE.findall(_code("import org.drools.model.PatternDSL; // org.drools.core.X"))
                if not ALLOWED.match(m)]


def test_no_python_module_loads_a_drools_implementation_class():
    offenders = []
    for path in sorted((ROOT / "gateway").rglob("*.py")):
        for k, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if re.search(r"""JClass\(\s*["'](?:org\.drools\.|org\.kie\.internal\.)""", line):
                offenders.append(f"{path.relative_to(ROOT)}:{k}: {line.strip()}")
    assert offenders == [], "load Drools' implementation through DroolsInternals instead:\n" + "\n".join(offenders)
