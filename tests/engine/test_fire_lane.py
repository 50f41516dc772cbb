"""The bulkhead's JVM lane (``Bulkhead.fire``, FireLane.java) over a real engine: a stateless fire
runs on the rule set's JVM threads while the event loop goes on, each caller gets its own answer,
the wait limit and errors arrive as :meth:`Engine.fire` would give them, and a loop's pipe goes
with the loop.

The slow rule waits in its then-part until the test creates a gate file (and creates a "started"
file first), so a test knows by a condition, not a sleep, that a fire is running.
"""

from __future__ import annotations

import asyncio
import gc
import os
import threading
from typing import Any

import pytest

from gateway.engine import Engine
from gateway.engine.bulkhead import Bulkhead
from gateway.engine.errors import FactError, Overloaded, RuleRuntimeError
from gateway.engine.results import finished
from gw_testing import GATED_JOB_DRL, Gate, run_async, wait_for

LANE_DRL = "package org.printeps.lanetest;\n\n" + GATED_JOB_DRL + """
declare Greeting
    id : String
    text : String
end

declare Boom
    id : String
end

rule "Greet"
when
    $g : Greeting( text == null )
then
    modify($g) { setText("hello " + $g.getId()) };
end

rule "Explode"
when
    Boom()
then
    throw new IllegalStateException("boom");
end
"""


@pytest.fixture()
def lane_engine(engine: Engine) -> Engine:
    engine.deploy("lane", {"lane.drl": LANE_DRL})
    return engine


async def _fire(engine: Engine, bulkhead: Bulkhead, facts: list[dict[str, Any]]) -> Any:
    prepared = engine.prepare_fire("lane", facts)
    answer, ms = await bulkhead.fire(prepared, engine.fire_timeout_ms)
    return finished(prepared, answer, ms)


def test_a_fire_runs_on_the_jvm_thread_while_the_loop_goes_on(lane_engine, tmp_path):
    bulkhead = Bulkhead("lane", workers=1, max_queue=8, max_wait_s=60)
    slow_gate = Gate(tmp_path, "slow")

    async def main() -> tuple[Any, int]:
        slow = asyncio.ensure_future(_fire(lane_engine, bulkhead, slow_gate.facts()))
        ticks = 0
        while not slow_gate.started.exists():  # the loop keeps running while the fire waits at its gate
            ticks += 1
            await asyncio.sleep(0.01)
        assert bulkhead.stats()["running"] == 1 and bulkhead.stats()["threads"] == 1
        slow_gate.open()
        return await slow, ticks

    result, ticks = run_async(main())
    assert ticks > 0 and [f["rule"] for f in result.fired] == ["Wait for the gate"]
    assert bulkhead.stats()["running"] == 0 and bulkhead.stats()["waiting"] == 0


def test_fires_of_one_loop_iteration_each_get_their_own_answer(lane_engine):
    """Fires submitted together (one JVM call) are answered each with its own facts, as Engine.fire
    answers them one by one."""
    bulkhead = Bulkhead("lane", workers=2, max_queue=64, max_wait_s=60)
    names = [f"guest{k}" for k in range(12)]

    async def main() -> list[Any]:
        return await asyncio.gather(*[_fire(lane_engine, bulkhead, [{"type": "Greeting", "id": n}]) for n in names])

    results = run_async(main())
    for name, result in zip(names, results):
        expected = lane_engine.fire("lane", [{"type": "Greeting", "id": name}], record=False)
        assert result.facts == expected.facts == [{"type": "Greeting", "id": name, "text": f"hello {name}"}]
        assert result.fired == expected.fired and result.version == expected.version
    assert bulkhead.stats()["running"] == 0 and bulkhead.stats()["waiting"] == 0


def test_a_fire_that_waited_too_long_is_refused_and_never_runs(lane_engine, tmp_path):
    bulkhead = Bulkhead("lane", workers=1, max_queue=8, max_wait_s=0.3)
    first, second = Gate(tmp_path, "first"), Gate(tmp_path, "second")

    async def main() -> tuple[Any, BaseException | None]:
        running = asyncio.ensure_future(_fire(lane_engine, bulkhead, first.facts()))
        while not first.started.exists():
            await asyncio.sleep(0.01)
        late = asyncio.ensure_future(_fire(lane_engine, bulkhead, second.facts()))
        await asyncio.sleep(0)  # submitted behind the running one
        assert bulkhead.stats()["waiting"] == 1
        await asyncio.sleep(0.6)  # past max_wait_s
        first.open()
        done = await running
        try:
            await late
        except Overloaded as exc:
            return done, exc
        return done, None

    done, refusal = run_async(main())
    assert [f["rule"] for f in done.fired] == ["Wait for the gate"]
    assert isinstance(refusal, Overloaded) and refusal.status == 503 and refusal.setting == "api.max_wait_s"
    assert not second.started.exists()  # refused before it fired
    assert bulkhead.stats()["refused"] == {"queue_full": 0, "waited": 1}


def test_a_full_queue_is_refused_at_once(lane_engine, tmp_path):
    bulkhead = Bulkhead("lane", workers=1, max_queue=1, max_wait_s=60)
    first, second = Gate(tmp_path, "a"), Gate(tmp_path, "b")

    async def main() -> Overloaded:
        running = asyncio.ensure_future(_fire(lane_engine, bulkhead, first.facts()))
        while not first.started.exists():
            await asyncio.sleep(0.01)
        queued = asyncio.ensure_future(_fire(lane_engine, bulkhead, second.facts()))
        await asyncio.sleep(0)
        with pytest.raises(Overloaded) as refused:
            await _fire(lane_engine, bulkhead, [{"type": "Greeting", "id": "x"}])
        first.open()
        second.open()
        await running
        await queued
        return refused.value

    refusal = run_async(main())
    assert refusal.status == 429 and refusal.setting == "api.max_queue" and refusal.limit == 1


def test_errors_arrive_as_engine_fire_gives_them(lane_engine):
    bulkhead = Bulkhead("lane", workers=1, max_queue=8, max_wait_s=60)

    async def main() -> None:
        with pytest.raises(RuleRuntimeError) as failed:
            await _fire(lane_engine, bulkhead, [{"type": "Boom", "id": "b"}])
        assert failed.value.rule == "Explode" and "boom" in str(failed.value)
        with pytest.raises(FactError):  # refused before anything is submitted
            await _fire(lane_engine, bulkhead, [{"type": "Dragon", "id": "d"}])

    run_async(main())
    with pytest.raises(RuleRuntimeError):
        lane_engine.fire("lane", [{"type": "Boom", "id": "b"}], record=False)
    assert bulkhead.stats()["running"] == 0 and bulkhead.stats()["waiting"] == 0


def test_a_loops_pipe_is_closed_with_the_loop(lane_engine):
    bulkhead = Bulkhead("lane", workers=1, max_queue=8, max_wait_s=60)

    def one_loop() -> None:
        async def main() -> None:
            await _fire(lane_engine, bulkhead, [{"type": "Greeting", "id": "g"}])
        # a plain thread: run_async's pool thread would keep nothing either, but be explicit
        thread = threading.Thread(target=lambda: asyncio.run(main()))
        thread.start()
        thread.join(60)

    one_loop()
    gc.collect()
    before = len(os.listdir("/proc/self/fd"))
    for _ in range(5):
        one_loop()
    gc.collect()
    assert wait_for(lambda: (gc.collect(), len(os.listdir("/proc/self/fd")))[1] <= before, 10), \
        (before, len(os.listdir("/proc/self/fd")))


def test_a_submission_the_jvm_refuses_fails_its_fires_and_frees_their_places(lane_engine):
    """If the JVM refuses the hand-over itself (an out-of-memory, a lane shut down), the callers get
    that error at once and the bulkhead counts nothing in flight; nothing hangs."""
    bulkhead = Bulkhead("lane", workers=1, max_queue=8, max_wait_s=60)

    class RefusingLane:
        def fire(self, *args: Any) -> None:
            raise RuntimeError("the lane refused it")

        fireMany = fire

        def threads(self) -> int:
            return 0

    bulkhead._java_lane = RefusingLane()

    async def main() -> list[Any]:
        return await asyncio.gather(*[_fire(lane_engine, bulkhead, [{"type": "Greeting", "id": f"g{k}"}])
                                      for k in range(3)], return_exceptions=True)

    outcomes = run_async(main())
    assert [str(o) for o in outcomes] == ["the lane refused it"] * 3
    assert bulkhead.in_java == 0 and bulkhead.stats()["waiting"] == 0 and bulkhead.stats()["running"] == 0
