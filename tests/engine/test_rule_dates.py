"""A bad ``date-effective``/``date-expires`` is a compile error at its file, line and column that
names the attribute and the form a date takes — on the plain path and on the compiled path (where
the executable model would otherwise fail only when the built unit loads, with a bare
InvocationTargetException) — and nothing is deployed: the live version stays (issue 30)."""

from __future__ import annotations

import dataclasses

import pytest

from gateway.engine import compiler, incremental
from gateway.engine.compiler import CompileOptions
from gateway.engine.errors import CompileFailed

TYPES = """package org.printeps.dates;
import org.printeps.gateway.Actions;
global Actions actions;

declare Visit
    id: String
    step: int
end
"""

PLAIN_THEN = 'actions.say("bot", "hello " + $v.getId());'
COMPILED_THEN = "modify($v) { setStep(1) }"  # not a plain then-part: always compiled


def rules(attribute: str, then: str) -> str:
    return ("package org.printeps.dates;\n\n"
            'rule "fine"\nwhen $v: Visit(step == 0)\nthen actions.say("bot", "fine");\nend\n\n'
            f'rule "dated"\n{attribute}\nwhen $v: Visit(step == 0)\nthen {then}\nend\n')


@pytest.fixture()
def options(tmp_path) -> CompileOptions:
    incremental.reset()
    yield CompileOptions(cache_dir=str(tmp_path / "units"))
    incremental.reset()


@pytest.mark.parametrize("plain", [True, False], ids=["plain", "compiled"])
@pytest.mark.parametrize("attribute", ["date-effective", "date-expires"])
def test_a_bad_rule_date_is_an_error_at_its_place(attribute, plain, options):
    options = dataclasses.replace(options, plain_rules=plain)
    for then in (PLAIN_THEN, COMPILED_THEN):
        files = {"types.drl": TYPES, "rules.drl": rules(f'no-loop true\n{attribute} "2020-01-31"', then)}
        with pytest.raises(CompileFailed) as failed:
            compiler.compile_files(files, "dates", options)
        [error] = failed.value.errors
        assert (error.file, error.line, error.column) == ("rules.drl", 10, len(attribute) + 2)
        assert error.message == (f"{attribute}: '2020-01-31' is not a date of the form d-MMM-yyyy (e.g. 1-Jan-2020)")


def test_dates_in_comments_and_texts_are_not_read_and_good_dates_build(options):
    then = 'actions.say("bot", "date-effective \\"soon\\" " + $v.getId());'
    files = {"types.drl": TYPES, "rules.drl": rules('// date-expires "never"\n/* date-effective "x" */\n'
                                                    'date-effective "01-JAN-2020"\ndate-expires "31-dec-2099"', then)}
    built = compiler.compile_files(files, "dates", options)
    assert (built.rule_count, built.stats.rules_built) == (2, 1)  # a text with escapes: the compiler's
    compiled = compiler.compile_files(files, "dates", CompileOptions(incremental=True, disk_cache=False, plain_rules=False))
    assert compiled.rule_count == 2


def test_a_bad_date_deploys_nothing(tmp_path):
    from gateway.config import Settings
    from gateway.engine import Engine

    engine = Engine(Settings(data_dir=str(tmp_path / "data"), engine={"rules_dir": str(tmp_path / "rules"),
                                                                     "compile_cache_dir": str(tmp_path / "units")}))
    good = {"types.drl": TYPES, "rules.drl": rules('date-effective "01-Jan-2020"', COMPILED_THEN)}
    engine.deploy("dates", good)
    before = engine.live_compiled("dates")
    with pytest.raises(CompileFailed) as failed:
        engine.deploy("dates", {"types.drl": TYPES, "rules.drl": rules('date-effective "Jan 1, 2020"', COMPILED_THEN)})
    assert "date-effective: 'Jan 1, 2020' is not a date of the form" in str(failed.value.errors[0])
    assert engine.live_compiled("dates") == before
    assert "dated" in [f["rule"] for f in engine.fire("dates", [{"type": "Visit", "id": "v1", "step": 0}]).fired]
