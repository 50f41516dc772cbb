"""The bulkhead on its own (no JVM): bounded threads, a bounded queue, refusals that say why."""

from __future__ import annotations

import threading

import pytest

from gateway.engine.bulkhead import Bulkhead
from gateway.engine.errors import Overloaded
from gw_testing import run_async, wait_for


def test_threads_are_bounded_and_the_queue_refuses_at_once_when_full():
    gate = threading.Event()
    bulkhead = Bulkhead("set", workers=2, max_queue=2, max_wait_s=60)
    done: list[object] = []
    for _ in range(4):  # two run, two wait
        bulkhead.submit(gate.wait, lambda result, error: done.append(error or result))
    assert wait_for(lambda: bulkhead.stats()["running"] == 2, 10)
    assert bulkhead.stats()["threads"] == 2 and bulkhead.stats()["waiting"] == 2
    with pytest.raises(Overloaded) as refused:
        bulkhead.submit(gate.wait, lambda result, error: None)
    assert refused.value.status == 429 and refused.value.setting == "api.max_queue" and refused.value.limit == 2
    assert refused.value.retry_after_s >= 1 and "'set'" in str(refused.value)
    gate.set()
    assert wait_for(lambda: len(done) == 4, 10) and all(d is True for d in done)
    assert bulkhead.stats()["refused"] == {"queue_full": 1, "waited": 0}


def test_a_fire_that_waited_too_long_is_refused_instead_of_run():
    gate = threading.Event()
    ran: list[str] = []
    bulkhead = Bulkhead("set", workers=1, max_queue=8, max_wait_s=0.2)
    answers: list[object] = []
    bulkhead.submit(lambda: (gate.wait(), ran.append("first")), lambda r, e: answers.append(e))
    bulkhead.submit(lambda: ran.append("second"), lambda r, e: answers.append(e))
    assert wait_for(lambda: bulkhead.stats()["running"] == 1, 10)
    assert not wait_for(lambda: bool(answers), 0.5)  # the second waits past max_wait_s behind the first
    gate.set()
    assert wait_for(lambda: len(answers) == 2, 10)
    assert answers[0] is None and isinstance(answers[1], Overloaded) and answers[1].status == 503
    assert ran == ["first"]  # the refused one never ran


def test_run_answers_on_the_event_loop_and_passes_errors_on():
    bulkhead = Bulkhead("set", workers=1, max_queue=4, max_wait_s=5)

    async def main() -> tuple[object, str]:
        value = await bulkhead.run(lambda: threading.current_thread().name)
        with pytest.raises(ZeroDivisionError):
            await bulkhead.run(lambda: 1 / 0)
        return value, threading.current_thread().name

    worker, loop_thread = run_async(main())
    assert worker == "fire-set" and loop_thread != worker


def test_idle_threads_go_away():
    bulkhead = Bulkhead("set", workers=2, max_queue=4, max_wait_s=5, idle_s=0.1)
    done = threading.Event()
    bulkhead.submit(lambda: None, lambda r, e: done.set())
    assert done.wait(10)
    assert wait_for(lambda: bulkhead.stats()["threads"] == 0, 10)
    done.clear()
    bulkhead.submit(lambda: None, lambda r, e: done.set())  # a new thread starts on demand
    assert done.wait(10)


def test_answers_that_finish_while_the_loop_is_busy_wake_it_once():
    """The hand-back is batched: three fires finishing while the loop is busy cost one
    call_soon_threadsafe (one write to the loop's wake-up pipe), and each caller gets its own answer."""
    import asyncio

    from gateway.engine import bulkhead as module

    bulkhead = Bulkhead("set", workers=3, max_queue=8, max_wait_s=60)
    gate = threading.Barrier(3)

    async def main() -> tuple[list[object], int]:
        loop = asyncio.get_running_loop()
        wakes: list[object] = []
        real = loop.call_soon_threadsafe

        def counted(callback, *args, **kwargs):  # type: ignore[no-untyped-def]
            wakes.append(callback)
            return real(callback, *args, **kwargs)

        loop.call_soon_threadsafe = counted  # type: ignore[method-assign]
        tasks = [asyncio.ensure_future(bulkhead.run(lambda k=k: (gate.wait(10), k)[1])) for k in range(3)]
        await asyncio.sleep(0)  # the three are submitted; the loop now stays busy until all three answered
        inbox = module._inbox_of(loop)
        assert wait_for(lambda: len(inbox._answers) == 3, 10)
        answers = await asyncio.gather(*tasks)
        return answers, len(wakes)

    answers, wakes = run_async(main())
    assert answers == [0, 1, 2] and wakes == 1
