"""Hot swap under load: clients fire continuously over real HTTP while 10 deploys/rollbacks happen.

Must hold: no failed request, and every answer names the version that served it — checked by
behaviour: each version greets with its own marker, so the greeting must match the named version.
"""

from __future__ import annotations

import threading

import httpx

from api_helpers import FACTS, files

CLIENTS = 2


def test_hot_swap_under_load(live_server, client):
    marker_of: dict[int, str] = {}
    first = client.put("/api/rulesets/swap", json={"files": files("m0")})
    assert first.status_code == 201
    marker_of[first.json()["version"]] = "m0"

    stop = threading.Event()
    answers: list[tuple[int, int | None, str]] = []
    failures: list[str] = []
    lock = threading.Lock()

    def fire_forever() -> None:
        with httpx.Client(base_url=live_server.url, timeout=30) as http:
            while not stop.is_set():
                try:
                    r = http.post("/api/rulesets/swap/fire", json={"facts": FACTS})
                except httpx.HTTPError as exc:
                    with lock:
                        failures.append(repr(exc))
                    continue
                body = r.json()
                text = body["actions"][0]["params"]["text"] if r.status_code == 200 else r.text
                with lock:
                    answers.append((r.status_code, body.get("version"), text))

    workers = [threading.Thread(target=fire_forever, daemon=True) for _ in range(CLIENTS)]
    for w in workers:
        w.start()
    try:
        with httpx.Client(base_url=live_server.url, timeout=120) as admin:
            # 10 changes: 6 deploys of new versions, 4 rollbacks to earlier ones.
            for step in range(1, 11):
                count_before = len(answers)
                if step % 5 in (2, 4):  # steps 2, 4, 7, 9: roll back to an earlier version
                    target = sorted(marker_of)[step % len(marker_of)]
                    r = admin.post("/api/rulesets/swap/rollback", json={"version": target})
                    assert r.status_code == 200, r.text
                else:
                    r = admin.put("/api/rulesets/swap", json={"files": files(f"m{step}")})
                    assert r.status_code == 201, r.text
                    marker_of[r.json()["version"]] = f"m{step}"
                # let the clients get some answers from this version before the next change
                waited = 0
                while len(answers) < count_before + 5 and waited < 500:
                    stop.wait(0.01)
                    waited += 1
    finally:
        stop.set()
        for w in workers:
            w.join(timeout=30)

    assert not failures, failures[:3]
    assert len(answers) > 20
    bad_status = [a for a in answers if a[0] != 200]
    assert not bad_status, bad_status[:3]
    for status, version, text in answers:
        assert version in marker_of, (version, text)
        assert text == f"Welcome c1 ({marker_of[version]})", (version, text)
    assert len({v for _, v, _ in answers}) >= 3  # the answers really came from several versions
