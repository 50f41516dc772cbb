"""Where the time of one event goes on the gateway's one-at-a-time paths (push, and the feed).

Usage (project venv): cd bench/peers && ../../.venv/bin/python gateway_profile.py [N]
Each stage is timed alone on the same events (best of 5 rounds of N, after a JIT warm-up), in
microseconds per event. Not part of engine_bench.py's report: it explains it.
"""

from __future__ import annotations

import sys
import time

import orjson

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
    from gateway.engine.results import decode_result, encode_facts_bytes

    engine = new_engine()
    engine.deploy("visitors", {"visitors.drl": SIMPLE_DRL})
    session = engine.open_session("visitors", record_facts=False)
    java = session.java
    events = [event(i) for i in range(n)]
    first = encode_facts_bytes([events[0]], 10)
    size = len(first)
    clock = [0]

    def push(i: int) -> None:
        clock[0] += 1
        session.push([events[i]], clock[0]).fired

    def raw_push(i: int) -> None:  # the one JVM call alone, input already in the shared buffer
        clock[0] += 1
        session._in_view[:size] = first
        java.pushBuffered(size, clock[0], 10_000, False)

    fired: list[int] = [0]
    feed = session.feed(lambda result: fired.__setitem__(0, fired[0] + len(result.fired)))

    def fed_round() -> float:
        start = time.perf_counter()
        for e in events:
            clock[0] += 1
            feed.submit([e], clock[0])
        feed.flush()
        return (time.perf_counter() - start) / n * 1e6

    for _ in range(4):  # warm-up: the JIT needs ~100k events
        best_us(push, n, 1)
        best_us(raw_push, n, 1)
        fed_round()
    session._in_view[:size] = first
    answer = bytes(session._out[: java.pushBuffered(size, clock[0] + 5_000, 10_000, False)])
    clock[0] += 6_000
    rows = [
        ("session.push([event], ts).fired (the public synchronous path)", best_us(push, n)),
        ("  its JVM call alone: pushBuffered (parse, build, clock, insert, fire, answer)", best_us(raw_push, n)),
        ("  one JPype call doing nothing (session.now()), for scale", best_us(lambda i: java.now(), n)),
        ("  Python: encode_facts_bytes([event])", best_us(lambda i: encode_facts_bytes([events[i]], 10**6), n)),
        ("  Python: decode_result(answer) (orjson + FireResult)", best_us(lambda i: decode_result(answer, "v", 1, 0.0), n)),
        ("  Python: orjson.loads(answer) alone", best_us(lambda i: orjson.loads(answer), n)),
        ("EventFeed.submit + callback, whole round incl. flush (the pipelined path)", min(fed_round() for _ in range(5))),
    ]
    print(f"answer: {len(answer)} bytes: {answer.decode()}")
    for label, us in rows:
        print(f"{us:8.2f} us  {label}")
    feed.close()
    session.close()


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20_000)
