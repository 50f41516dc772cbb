"""A failure that repeats once per decision (no robot connected) is logged once a minute, with how
many like it were held back; every outcome is still recorded and announced."""

from __future__ import annotations

import logging

from gateway.base.logs import RepeatLimiter
from gateway.runtime.actions import ActionRouter


class FakeClock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def test_a_repeated_failure_is_logged_once_a_window_with_the_count_held_back(caplog):
    clock = FakeClock()
    router = ActionRouter()
    router._repeats = RepeatLimiter(60.0, clock)
    heard: list[dict] = []
    router.add_listener(heard.append)
    router.register("say", lambda action, context: {"status": "no_service", "message": "no robot 'pepper'"})
    try:
        with caplog.at_level(logging.INFO, logger="gateway.runtime.actions"):
            for _ in range(50):
                router.perform({"module": "say", "params": {"robot": "pepper"}})
            router.perform({"module": "move", "params": {}})  # another kind of failure: its own line
            clock.now += 61
            router.perform({"module": "say", "params": {"robot": "pepper"}})
    finally:
        router.close()
    errors = [r.getMessage() for r in caplog.records if r.levelno == logging.ERROR]
    assert errors == [
        "action say: no_service no robot 'pepper'",
        "action move: unsupported no handler for module 'move' on this gateway (known: say)",
        "action say: no_service no robot 'pepper' (49 more like it in the last 60 s not logged)",
    ]
    assert len(heard) == 52  # every outcome announced (and recorded) all the same


def test_the_limiter_counts_per_key():
    clock = FakeClock()
    limiter = RepeatLimiter(10.0, clock)
    assert limiter.check("a") == (True, 0)
    assert limiter.check("a") == (False, 0)
    assert limiter.check("b") == (True, 0)
    clock.now += 10
    assert limiter.check("a") == (True, 1)
    assert limiter.check("a") == (False, 0)
