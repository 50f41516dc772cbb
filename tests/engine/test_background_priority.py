"""Background work runs at a lower CPU priority than serving when ``engine.background_nice`` asks
for it (gateway.base.priority): the threads that compile rule units and explain queries lower
themselves when they start, and the thread that asked (a deploy, a fire) keeps its own. Off by
default. Real JVM compiles; the priority is read from the kernel."""

from __future__ import annotations

import uuid

import pytest

from gateway.base import priority
from gateway.config import Settings
from gateway.engine import Engine, explain, incremental

from engine_samples import TYPES

COMPILED = """package org.printeps.test;
rule "older {tag}"
when
    $p : Customer( age < 100 )
then
    modify( $p ) {{ setAge( 100 ) }};
end
"""


@pytest.fixture()
def lowering(tmp_path):
    """An engine whose background threads run 10 steps lower (the setting is the process's: put
    back to the default afterwards, so later tests of this worker compile as before)."""
    engine = Engine(Settings(data_dir=str(tmp_path / "data"), engine={
        "rules_dir": str(tmp_path / "rules"), "background_nice": 10, "explain_prebuild": False}))
    yield engine
    priority.configure(0)


@pytest.fixture()
def compile_threads(monkeypatch):
    """The nice value of each thread a rule unit is compiled on."""
    seen: list[int] = []
    build_unit = incremental.build_unit

    def recorded(*args, **kwargs):
        seen.append(priority.thread_nice())
        return build_unit(*args, **kwargs)

    monkeypatch.setattr(incremental, "build_unit", recorded)
    return seen


def test_rule_units_compile_on_threads_below_the_callers(lowering, compile_threads):
    engine = lowering
    own = priority.thread_nice()
    engine.deploy("lowered", {"types.drl": TYPES, "rules.drl": COMPILED.format(tag=uuid.uuid4().hex)})
    assert compile_threads and set(compile_threads) == {min(19, own + 10)}
    assert priority.thread_nice() == own  # the deploying thread is not lowered
    assert engine.fire("lowered", [{"type": "Customer", "id": "p", "age": 3}]).fired


def test_explanations_run_on_a_lowered_thread_and_zero_keeps_the_priority(lowering, compile_threads):
    engine = lowering
    own = priority.thread_nice()
    cache = explain.ExplainCache()
    try:
        assert cache._worker.submit(priority.thread_nice).result(30) == min(19, own + 10)
    finally:
        cache.close()
    priority.configure(0)  # the default
    engine.deploy("as-serving", {"types.drl": TYPES, "rules.drl": COMPILED.format(tag=uuid.uuid4().hex)})
    assert compile_threads and set(compile_threads) == {own}
    assert Settings().engine.background_nice == 0
