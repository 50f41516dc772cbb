"""Write-behind: records leave the caller at once and all reach the store, in order."""

from __future__ import annotations

import threading
import time

from gateway.store.write_behind import WriteBehind


class SlowStore:
    def __init__(self) -> None:
        self.docs: list[tuple[str, dict, str]] = []
        self.lock = threading.Lock()

    def record(self, collection, doc, *, stored_type, inserted_by="gateway"):
        time.sleep(0.001)
        with self.lock:
            self.docs.append((collection, doc, stored_type))
        return "id"


def test_everything_queued_is_written_in_order_on_close():
    store = SlowStore()
    writer = WriteBehind(store, max_queued=10)  # smaller than the burst: back-pressure, nothing dropped
    for i in range(50):
        writer.record("rule_firings", {"n": i}, stored_type="printeps/RuleFiring")
    writer.close()
    assert [d[1]["n"] for d in store.docs] == list(range(50))


def test_a_failing_write_does_not_stop_the_writer():
    class Flaky(SlowStore):
        def record(self, collection, doc, *, stored_type, inserted_by="gateway"):
            if doc.get("n") == 1:
                raise RuntimeError("boom")
            return super().record(collection, doc, stored_type=stored_type)

    store = Flaky()
    writer = WriteBehind(store)
    for i in range(3):
        writer.record("c", {"n": i}, stored_type="t")
    writer.close()
    assert [d[1]["n"] for d in store.docs] == [0, 2]


def test_bursts_are_written_in_batches_through_the_real_store(store):
    writer = WriteBehind(store)
    for i in range(300):
        writer.record("rule_firings", {"n": i}, stored_type="printeps/RuleFiring")
    writer.close()
    docs = store.query("rule_firings", type="printeps/RuleFiring", limit=1000, newest_first=False)
    assert [d["n"] for d in docs] == list(range(300))
