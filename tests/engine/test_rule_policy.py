"""The rule policy on DRL text (gateway.engine.policy): what an author's rules may name and call.

Plain Python (no JVM): the lexer, name resolution and the allow list. The policy over whole rule
sets (DSL, decision tables, the shipped sets) and at every entry point is in
tests/api/test_rule_policy_api.py.
"""

from __future__ import annotations

import pytest

from gateway.engine.policy import DEFAULT_ALLOW, RulePolicy, applies_to, tokenize

HEADER = """package org.example.shop;
import org.printeps.gateway.Actions;
global Actions actions;
declare Customer
    id : String
    age : int
    tags : java.util.List
    since : java.time.LocalDate
end
"""


def violations(drl: str, *allow: str) -> list[tuple[int, int, str]]:
    found = RulePolicy(tuple(allow)).check([("r.drl", drl)])["r.drl"]
    return [(v.line, v.column, v.name) for v in found]


def rule(then: str, when: str = "$c : Customer( age > 3 )") -> str:
    return HEADER + f'rule "r"\nwhen\n    {when}\nthen\n    {then}\nend\n'


# where the rule's then-part starts in rule(): line 14, column 5
THEN = 14


def test_an_owners_rules_pass():
    drl = rule('modify($c) { setAge($c.getAge() + 1), setId("x" + $c.getId()) }\n'
               '    insert(new Customer("c2", 3, new java.util.ArrayList(), java.time.LocalDate.now()));\n'
               '    actions.say("pepper", "Hello " + $c.getId() + " " + Math.max(1, 2) + String.valueOf(3));\n'
               '    java.util.List<String> names = new java.util.ArrayList<>(); names.add(drools.getRule().getName());\n'
               '    update($c); retract($c); delete($c); insertLogical(new Customer());\n'
               '    java.util.Map<String, Integer> m = java.util.Map.of("a", 1); m.forEach((k, v) -> names.add(k));',
               when='$c : Customer( age > 3, $id : id, getAge() < 99, id != "x" )\n'
                    '    not Customer( id == "y" )\n'
                    '    $n : Number( intValue > 1 ) from accumulate( Customer( $a : age ), sum( $a ) )\n'
                    '    $t : String() from $c.getTags()\n'
                    '    eval( $c.getAge() > 2 && Integer.parseInt("3") == 3 )')
    assert violations(drl) == []


def test_text_in_strings_and_comments_is_not_code():
    drl = rule('actions.say("pepper", "System.exit(0); Runtime.getRuntime()"); // Runtime.getRuntime()\n'
               '    /* java.nio.file.Files.delete(x) */ actions.say("a", \'Thread.sleep(1)\');')
    assert violations(drl) == []


@pytest.mark.parametrize("then, name", [
    ('java.nio.file.Files.writeString(java.nio.file.Path.of("/tmp/x"), "x");', "java.nio.file.Files"),
    ('Runtime.getRuntime().exec("touch /tmp/x");', "java.lang.Runtime"),
    ('System.exit(1);', "java.lang.System"),
    ('new Thread(() -> {}).start();', "java.lang.Thread"),
    ('new ProcessBuilder("ls").start();', "java.lang.ProcessBuilder"),
    ('Class.forName("x");', "java.lang.Class"),
    ('$c.getClass().getMethods();', "getClass"),
    ('String.class.getName();', "class"),
    ('java.lang.reflect.Method m = null;', "java.lang.reflect.Method"),
    ('java.lang.invoke.MethodHandles.lookup();', "java.lang.invoke.MethodHandles"),
    ('new java.io.File("/tmp/x").delete();', "java.io.File"),
    ('new java.net.Socket("h", 1);', "java.net.Socket"),
    ('Object o = (Runtime) null;', "java.lang.Runtime"),
    ('java.util.function.Supplier<Object> s = Runtime::getRuntime;', "java.lang.Runtime"),
    ('drools.getKieRuntime().getKieBase();', "drools.getKieRuntime"),
    ('exec("x");', "exec"),
])
def test_refused_then_parts_are_named_where_they_stand(then, name):
    found = violations(rule(then))
    assert found and found[0][0] == THEN and found[0][2] == name, found
    assert found[0][1] >= 5


def test_imports_are_classes_and_refused_unless_allowed():
    drl = HEADER.replace("import org", "import java.nio.file.Files;\nimport java.io.*;\nimport static java.lang.System.exit;\nimport org") + \
        'rule "r" when Customer() then Files.delete(null); exit(0); end\n'
    found = violations(drl)
    assert ("java.nio.file.Files" in [n for _, _, n in found] and "java.io.*" in [n for _, _, n in found]
            and "java.lang.System" in [n for _, _, n in found]), found
    assert (2, 8, "java.nio.file.Files") in found  # the import itself, at its line and column


def test_functions_eval_and_from_are_checked_like_then_parts():
    function = HEADER + 'function String leak(String p) {\n    return Class.forName(p).getName();\n}\n'
    assert violations(function) == [(11, 12, "java.lang.Class")]
    ok_function = HEADER + 'function int twice(int n) { return n * 2; }\nrule "r" when Customer( age == twice(2) ) then actions.say("a", "" + twice(3)); end\n'
    assert violations(ok_function) == []
    evaluated = rule("update($c);", when='Customer()\n    eval( System.getenv("HOME") != null )')
    assert [n for _, _, n in violations(evaluated)] == ["java.lang.System"]
    source = rule("update($c);", when='$f : String() from java.nio.file.Files.readAllLines(java.nio.file.Path.of("/etc/passwd"))')
    assert [n for _, _, n in violations(source)][0] == "java.nio.file.Files"


def test_globals_and_declared_types_are_classes_too():
    assert [n for _, _, n in violations(HEADER + "global java.lang.Runtime rt;\n")] == ["java.lang.Runtime"]
    assert [n for _, _, n in violations(HEADER + "declare Evil extends java.io.File end\n")] == ["java.io.File"]
    assert [n for _, _, n in violations(HEADER + "declare Evil\n  f : java.io.File\nend\n")] == ["java.io.File"]
    assert violations(HEADER + "declare enum Color RED(\"r\"), GREEN(\"g\"); label : String end\n") == []


def test_a_variable_named_like_a_package_is_checked_under_both_readings():
    # `java` could be a local variable or the package: the compiler picks; the policy checks both
    drl = rule('String java = ""; java.lang.Runtime.getRuntime();')
    assert [n for _, _, n in violations(drl)] == ["java.lang.Runtime"]


def test_the_allowed_list_is_extendable_by_class_and_by_package():
    drl = rule('com.example.Pricing.discount(3); com.example.tax.Vat.of(2);')
    assert {n for _, _, n in violations(drl)} == {"com.example.Pricing", "com.example.tax.Vat"}
    assert [n for _, _, n in violations(drl, "com.example.Pricing")] == ["com.example.tax.Vat"]
    assert violations(drl, "com.example") == []
    assert violations(drl, "com.example.*") == []


def test_the_default_list_is_values_only():
    assert "java.time" in DEFAULT_ALLOW and "java.lang.String" in DEFAULT_ALLOW
    policy = RulePolicy()
    for refused in ("java.lang.System", "java.lang.Runtime", "java.lang.Thread", "java.lang.Class",
                    "java.lang.ClassLoader", "java.lang.ProcessBuilder", "java.lang.reflect.Method",
                    "java.lang.invoke.MethodHandles", "java.io.File", "java.nio.file.Files", "java.net.URL",
                    "java.util.concurrent.Executors", "java.util.ServiceLoader", "java.util.Scanner"):
        assert not policy.allows_class(refused), refused
    for allowed in ("java.lang.String", "java.lang.Math", "java.time.LocalDate", "java.time.format.DateTimeFormatter",
                    "java.util.ArrayList", "java.util.Map.Entry", "java.math.BigDecimal", "org.printeps.gateway.Actions"):
        assert policy.allows_class(allowed), allowed


def test_a_rule_set_may_not_live_in_the_jdks_packages():
    assert [n for _, _, n in violations("package java.util.concurrent;\nrule \"r\" when then end\n")] == \
        ["java.util.concurrent"]


def test_who_is_checked():
    assert applies_to("author") and applies_to("caller")
    assert not applies_to("developer") and not applies_to(None)


def test_the_lexer_keeps_positions_and_skips_strings_chars_and_comments():
    tokens = tokenize('a.b("x\\"y", \'c\') // z\n  /* q\n r */ """\nt u""" d')
    assert [(t.kind, t.text) for t in tokens][:6] == [("id", "a"), ("op", "."), ("id", "b"), ("op", "("),
                                                      ("str", '"x\\"y"'), ("op", ",")]
    assert tokens[-1].text == "d" and (tokens[-1].line, tokens[-1].column) == (4, 8)
    assert [t.kind for t in tokenize('""" x')] == ["str", "str"]  # no line break: "" and an open string


def test_names_are_read_as_javac_reads_them():
    # a unicode escape closes the string for javac, so what follows is code
    assert [n for _, _, n in violations(rule('actions.say("a", "\\u0022); System.exit(0); //");'))] == \
        ["java.lang.System"]
    assert violations(rule('actions.say("a", "caf\\u00e9 \\\\u0022 System.exit(0)");')) == []  # an escaped backslash
    # characters javac ignores inside identifiers do not split a name
    assert [n for _, _, n in violations(rule('new java\u200b.io.File("x").delete();'))] == ["java.io.File"]
    assert [n for _, _, n in violations(rule('Sys\u00adtem.exit(0);'))] == ["java.lang.System"]
    # three quotes open a text block only before a line break (else: "" and a string)
    assert [n for _, _, n in violations(rule('String s = """" + Runtime.getRuntime() + """";'))] == \
        ["java.lang.Runtime"]


def test_a_type_declared_in_another_package_does_not_shadow_java_lang():
    other = "package org.example.elsewhere;\ndeclare Runtime\n    id : String\nend\n"
    here = 'package org.example.shop;\nrule "r" when then Runtime.getRuntime().exec("x"); end\n'
    found = RulePolicy().check([("a.drl", other), ("b.drl", here)])
    assert [v.name for v in found["b.drl"]] == ["java.lang.Runtime"] and found["a.drl"] == []
    same = 'package org.example.elsewhere;\nrule "r" when then Runtime r = new Runtime(); end\n'
    assert RulePolicy().check([("a.drl", other), ("c.drl", same)])["c.drl"] == []


def test_nothing_at_the_top_level_escapes_the_check():
    assert [n for _, _, n in violations(HEADER + 'import java.util.List function void f() { System.exit(0); }\n')] == \
        ["java.lang.System"]
    assert [n for _, _, n in violations(HEADER + 'dialect "java" java.lang.Runtime.getRuntime();\n')] == \
        ["java.lang.Runtime"]
    drl = HEADER + "global Actions java;\n" + 'rule "r" when then java.lang.Runtime.getRuntime(); end\n'
    assert [n for _, _, n in violations(drl)] == ["java.lang.Runtime"]  # a global named like a package


def test_static_imports_of_allowed_classes():
    drl = HEADER.replace("import org", "import static java.lang.Math.*;\nimport static java.lang.String.valueOf;\nimport org")
    assert violations(drl + 'rule "r" when then actions.say("a", valueOf(max(1, abs(-2)))); end\n') == []
    refused = HEADER.replace("import org", "import static java.lang.System.*;\nimport org")
    assert [n for _, _, n in violations(refused + 'rule "r" when then exit(0); end\n')] == ["java.lang.System", "exit"]


def test_only_top_level_items_declare_names():
    drl = HEADER + 'rule "r" when then\n    int x = 0;\n    declare Runtime = null;\nend\nrule "s" when then Runtime.getRuntime(); end\n'
    assert "java.lang.Runtime" in [n for _, _, n in violations(drl)]
