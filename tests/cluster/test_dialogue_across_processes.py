"""Spoken dialogue across real gateway processes over one MongoDB-protocol server: a table's
conversation is kept in the Information State, so its turns may reach any process (``--workers``,
several hosts) and it goes on after the process that took its first turns is killed."""

from __future__ import annotations

import shutil
import signal
import threading
from pathlib import Path

import httpx
import pytest
import yaml
from test_processes import Process, process_env, stop_all, wait_for

pytestmark = pytest.mark.slow
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def home(tmp_path_factory, mongo):
    home = tmp_path_factory.mktemp("dialogue-cluster")
    shutil.copytree(ROOT / "rules" / "drl" / "dialogue", home / "rules" / "dialogue")
    config = home / "printeps.yaml"
    config.write_text(yaml.safe_dump({
        "data_dir": str(home / "var"),
        "engine": {"rules_dir": str(home / "rules")},
        "store": {"database": "dialogue_cluster"},
        "streams": {"queries_dir": None},
        "sessions": {"member_heartbeat_s": 1.0},
    }))
    return home, config, process_env(mongo.uri)


def turn(url: str, conversation: str, text: str) -> dict:
    r = httpx.post(f"{url}/api/dialogue/turns", json={"conversation": conversation, "text": text}, timeout=60)
    assert r.status_code == 200, r.text
    return r.json()


def orders_of(url: str, conversation: str) -> list[dict]:
    r = httpx.get(f"{url}/api/dialogue/orders", params={"limit": 100}, timeout=30)
    assert r.status_code == 200, r.text
    return [o for o in r.json()["orders"] if o["conversation"] == conversation]


def test_one_conversation_whichever_process_takes_the_turn_and_after_its_process_is_killed(home):
    folder, config, env = home
    a, b = Process("DA", config, env, folder).start(), Process("DB", config, env, folder).start()
    try:
        a.ready()
        b.ready()
        # turn 1 on A, the answer to Pepper's question on B, the confirmation on A again
        first = turn(a.url, "table1", "I'd like coffee please")
        assert first["says"] == ["How many cups of coffee?"] and first["turn"] == 1
        second = turn(b.url, "table1", "two")
        assert second["turn"] == 2 and second["slots"] == {"drink": "coffee", "cups": 2}
        assert second["says"] == ["2 coffees, certainly. Is that right?"] and second["state"] == "confirming"
        done = turn(a.url, "table1", "yes")
        assert done["turn"] == 3 and done["state"] == "ordered"
        assert wait_for(lambda: orders_of(b.url, "table1"), 30), "the order never reached the Information State"
        (order,) = orders_of(b.url, "table1")
        assert (order["drink"], order["cups"], order["table"]) == ("coffee", 2, "table1")
        assert order["decision_ids"] == [first["decision_id"], second["decision_id"], done["decision_id"]]

        # two turns of one conversation at once, one on each process: both count, one after the other
        answers: list[dict] = []
        threads = [threading.Thread(target=lambda u=u, t=t: answers.append(turn(u, "table3", t)))
                   for u, t in ((a.url, "coffee"), (b.url, "three"))]
        for t in threads:
            t.start()
        for t in threads:
            t.join(120)
        assert sorted(x["turn"] for x in answers) == [1, 2]
        last = max(answers, key=lambda x: x["turn"])
        assert last["slots"] == {"drink": "coffee", "cups": 3} and last["state"] == "confirming"

        # A is killed in the middle of table2's conversation: B goes on with it where A left it
        asked = turn(a.url, "table2", "green tea please")
        assert asked["says"] == ["How many cups of green tea?"]
        a.proc.send_signal(signal.SIGKILL)
        a.proc.wait(timeout=30)
        going = httpx.get(f"{b.url}/api/dialogue/conversations", timeout=30).json()["going_on"]
        table2 = next(c for c in going if c["conversation"] == "table2")
        assert table2["turns"] == 1 and table2["state"] == "ordering" and table2["process"].endswith(f":{a.proc.pid}")
        cont = turn(b.url, "table2", "three")
        assert cont["turn"] == 2 and cont["slots"] == {"drink": "green tea", "cups": 3}
        assert cont["says"] == ["3 green teas, certainly. Is that right?"]
        assert turn(b.url, "table2", "yes")["state"] == "ordered"
        assert wait_for(lambda: orders_of(b.url, "table2"), 30)
        (kept,) = orders_of(b.url, "table2")
        assert (kept["drink"], kept["cups"]) == ("green tea", 3) and kept["decision_ids"][0] == asked["decision_id"]
    finally:
        stop_all(a, b)


def test_workers_carry_one_conversation_on_the_shared_port(home):
    folder, config, env = home
    served = Process("DW", config, env, folder, "--workers", "2").start()
    try:
        served.ready()
        writers = set()
        for k in range(24):  # new connections: the kernel spreads them over both workers
            text = ("coffee", "two", "no")[k % 3]
            answer = turn(served.url, "table9", text)
            assert answer["turn"] == k + 1, answer  # one conversation, whichever worker took the turn
            assert answer["state"] == ("ordering", "confirming", "ordering")[k % 3]
            going = httpx.get(f"{served.url}/api/dialogue/conversations", timeout=30).json()["going_on"]
            writers.add(next(c["process"] for c in going if c["conversation"] == "table9"))
        assert len(writers) == 2, writers  # both workers took turns of it
    finally:
        served.stop()
