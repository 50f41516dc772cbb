"""Where the time of one event goes on the gateway's one-at-a-time path (insert_event + fire).

Usage (project venv): cd bench/peers && ../../.venv/bin/python gateway_profile.py [N]
Each stage is timed alone on the same events (best of 5 rounds of N, after a JIT warm-up), in
microseconds per event. Not part of engine_bench.py's report: it explains it.
"""

from __future__ import annotations

import json
import sys
import time

from common import event
from gateway_peer import SIMPLE_DRL, new_engine


def best_us(fn, n: int, rounds: int = 5) -> float:
    times = []
    for _ in range(rounds):
        start = time.perf_counter()
        for i in range(n):
            fn(i)
        times.append((time.perf_counter() - start) / n * 1e6)
    return min(times)


def main(n: int) -> None:
    from gateway.engine.results import decode_result, encode_facts
    from gateway.engine.session import _check

    engine = new_engine()
    engine.deploy("visitors", {"visitors.drl": SIMPLE_DRL})
    session = engine.open_session("visitors")
    java = session._java
    events = [event(i) for i in range(n)]
    encoded = [encode_facts([e], 10**6) for e in events]
    clock = [0]

    def public(i: int) -> None:
        clock[0] += 1
        session.insert_event(events[i], clock[0])
        session.fire()

    def raw_java(i: int) -> None:  # the two Java calls with pre-encoded input, answers left in Java
        clock[0] += 1
        java.insertAt(encoded[i], clock[0])
        java.fire(10_000, False)

    def raw_java_no_clock(i: int) -> None:
        java.insertAt(encoded[i], clock[0])
        java.fire(10_000, False)

    for _ in range(3):  # warm-up
        best_us(public, n, 1)
        best_us(raw_java, n, 1)
    clock[0] += 10_000
    java.advanceBy(10_000)
    clock[0] += 1
    java.insertAt(encoded[0], clock[0])
    answer_java = java.fire(10_000, False)
    answer = str(answer_java)
    insert_answer = str(java.insertAt(encoded[1], clock[0]))
    java.fire(10_000, False)
    rows = [
        ("public path: session.insert_event + session.fire", best_us(public, n)),
        ("  Java side, 2 JPype calls, pre-encoded input (parse, build, clock, insert, fire, answer)", best_us(raw_java, n)),
        ("  the same without moving the pseudo clock (no expiry work)", best_us(raw_java_no_clock, n)),
        ("  one JPype call doing nothing (session.now()), for scale", best_us(lambda i: java.now(), n)),
        ("  Python: encode_facts([event])", best_us(lambda i: encode_facts([events[i]], 10**6), n)),
        ("  Python: _check(insert answer) (str + json.loads)", best_us(lambda i: _check(insert_answer), n)),
        ("  Python: str(fire answer)", best_us(lambda i: str(answer_java), n)),
        ("  Python: decode_result(fire answer) (json.loads + FireResult)", best_us(lambda i: decode_result(answer, "v", 1, 0.0), n)),
    ]
    print(f"fire answer: {len(answer)} chars: {answer}")
    for label, us in rows:
        print(f"{us:8.2f} us  {label}")
    session.close()


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20_000)
