"""Replay over REST: recorded decisions re-fired on a candidate (real JVM, real MongoDB-protocol
server). The expected changes are computed here from the generated facts, not read back from the
gateway; a replay must leave the live version, the decisions and the actions exactly as they were."""

from __future__ import annotations

import random

import pytest

from test_jobs import ASYNC, follow

RULES = """package org.printeps.replaytest;

import org.printeps.gateway.Actions;

global Actions actions;

declare Guest
    id : String
    age : int
end

rule "Child"
when
    $g : Guest( age < THRESHOLD )
then
    actions.say("pepper", "Hello little " + $g.getId());
end

rule "Grown-up"
when
    $g : Guest( age >= THRESHOLD )
then
    actions.say("pepper", "Welcome " + $g.getId());
end
"""


def guest_rules(threshold: int) -> dict[str, str]:
    return {"guests.drl": RULES.replace("THRESHOLD", str(threshold))}


def generated(seed: int, count: int) -> list[list[dict]]:
    """``count`` fact lists of 1 to 3 guests aged 0 to 40."""
    rng = random.Random(seed)
    return [[{"type": "Guest", "id": f"g{i}-{k}", "age": rng.randint(0, 40)} for k in range(rng.randint(1, 3))]
            for i in range(count)]


def deploy(client, name: str, threshold: int) -> int:
    response = client.put(f"/api/rulesets/{name}", json={"files": guest_rules(threshold)})
    assert response.status_code == 201, response.text
    return response.json()["version"]


def record(client, name: str, fact_lists: list[list[dict]]) -> None:
    for facts in fact_lists:
        response = client.post(f"/api/rulesets/{name}/fire", json={"facts": facts})
        assert response.status_code == 200, response.text


def live_state(client, api_gateway, name: str) -> dict:
    """What must not move: the live version, the decisions recorded and the robots' action outcomes."""
    api_gateway.store.flush(30)
    db = api_gateway.store.db
    return {"version": client.get(f"/api/rulesets/{name}").json()["version"],
            "decisions": db["decisions"].count_documents({"ruleset": name}),
            "outcomes": db["actions"].count_documents({}),
            # what the live version does, asked without recording a decision
            "said": [a["params"]["text"] for a in api_gateway.engine.fire(
                name, [{"type": "Guest", "id": "probe", "age": 11}], record=False).actions]}


@pytest.fixture(scope="module")
def recorded(client):
    """Rule set ``replay-a`` (threshold 12) with 120 recorded decisions."""
    name = "replay-a"
    deploy(client, name, 12)
    facts = generated(29, 120)
    record(client, name, facts)
    return name, facts


def test_a_draft_replay_counts_exactly_what_changes(client, api_gateway, recorded):
    name, facts = recorded
    before = live_state(client, api_gateway, name)
    changed = [f for f in facts if any(10 <= g["age"] < 12 for g in f)]
    ages = [g["age"] for f in facts for g in f]
    answer = client.post(f"/api/rulesets/{name}/replay", json={"files": guest_rules(10)})
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert body["ruleset"] == name and "hash" in body["candidate"]
    assert body["replayed"] == len(facts) == before["decisions"]
    assert body["changed"] == len(changed) and body["unchanged"] == len(facts) - len(changed)
    assert body["failed"] == 0 and body["not_replayable"] == 0
    rules = {r["rule"]: (r["before"], r["after"]) for r in body["rules"]}
    assert rules["Child"] == (sum(a < 12 for a in ages), sum(a < 10 for a in ages))
    assert rules["Grown-up"] == (sum(a >= 12 for a in ages), sum(a >= 10 for a in ages))
    assert len(body["changes"]) == min(len(changed), 100)
    change = body["changes"][0]
    assert change["before"]["version"] == 1 and "Child" in change["before"]["fired"]
    assert "Grown-up" in change["after"]["fired"]
    assert any(a["params"]["text"].startswith("Welcome") for a in change["after"]["actions"])
    assert live_state(client, api_gateway, name)["version"] == before["version"]


def test_nothing_live_moves(client, api_gateway, recorded):
    name, _facts = recorded
    before = live_state(client, api_gateway, name)
    body = client.post(f"/api/rulesets/{name}/replay", json={"files": guest_rules(5), "max_changes": 3}).json()
    assert body["replayed"] > 0 and len(body["changes"]) == 3 and body["changes_truncated"] is True
    after = live_state(client, api_gateway, name)
    assert after["version"] == before["version"]
    assert after["decisions"] == before["decisions"]
    assert after["outcomes"] == before["outcomes"]
    assert after["said"] == before["said"] == ["Hello little probe"]  # still threshold 12


def test_a_replay_of_the_live_text_changes_nothing(client, recorded):
    name, facts = recorded
    by_files = client.post(f"/api/rulesets/{name}/replay", json={"files": guest_rules(12)}).json()
    assert by_files["changed"] == 0 and by_files["unchanged"] == by_files["replayed"] >= len(facts)
    by_version = client.post(f"/api/rulesets/{name}/replay", json={"version": 1}).json()
    assert by_version["candidate"] == {"version": 1}
    assert by_version["changed"] == 0 and by_version["replayed"] == by_files["replayed"]
    assert all(r["before"] == r["after"] for r in by_version["rules"])


def test_the_selection_limits_and_filters(client, recorded):
    name, _facts = recorded
    limited = client.post(f"/api/rulesets/{name}/replay", json={"version": 1, "limit": 7}).json()
    assert limited["replayed"] == 7 and limited["matching"] > 7 and "newest 7" in limited["note"]
    future = client.post(f"/api/rulesets/{name}/replay",
                         json={"version": 1, "since": "2100-01-01T00:00:00Z"})
    assert future.status_code == 200
    assert future.json()["replayed"] == 0 and "nothing was replayed" in future.json()["note"]
    other_origin = client.post(f"/api/rulesets/{name}/replay", json={"version": 1, "origin": "kie"}).json()
    assert other_origin["replayed"] == 0


def test_bad_requests_are_told_and_change_nothing(client, api_gateway, recorded):
    name, _facts = recorded
    before = live_state(client, api_gateway, name)
    broken = client.post(f"/api/rulesets/{name}/replay",
                         json={"files": {"guests.drl": guest_rules(10)["guests.drl"].replace("age < 10", "age <")}})
    assert broken.status_code == 422
    errors = broken.json()["errors"]
    assert errors and errors[0]["file"] == "guests.drl" and errors[0]["line"] > 0 and "column" in errors[0]
    unknown = client.post(f"/api/rulesets/{name}/replay", json={"version": 99})
    assert unknown.status_code == 404 and "99" in unknown.json()["error"]
    over = client.post(f"/api/rulesets/{name}/replay", json={"version": 1, "limit": 100_001})
    assert over.status_code == 422 and over.json()["errors"][0]["field"] == "limit"
    both = client.post(f"/api/rulesets/{name}/replay", json={"version": 1, "files": guest_rules(3)})
    assert both.status_code == 422
    bad_time = client.post(f"/api/rulesets/{name}/replay", json={"version": 1, "since": "yesterday"})
    assert bad_time.status_code == 422 and bad_time.json()["errors"][0]["field"] == "since"
    no_set = client.post("/api/rulesets/no-such-set/replay", json={"version": 1})
    assert no_set.status_code == 404
    after = live_state(client, api_gateway, name)
    assert (after["version"], after["decisions"], after["outcomes"]) == \
           (before["version"], before["decisions"], before["outcomes"])


def test_cut_and_session_decisions_are_reported_not_compared(client, api_gateway):
    name = "replay-b"
    deploy(client, name, 12)
    keep = api_gateway.engine.recorder.max_facts
    many = [{"type": "Guest", "id": f"m{i}", "age": 11} for i in range(keep + 5)]
    record(client, name, [many, [{"type": "Guest", "id": "plain", "age": 11}]])
    session = client.post(f"/api/rulesets/{name}/sessions", json={})
    assert session.status_code == 201, session.text
    sid = session.json()["id"]
    fired = client.post(f"/api/rulesets/{name}/sessions/{sid}/facts",
                        json={"facts": [{"type": "Guest", "id": "s1", "age": 11}], "fire": True})
    assert fired.status_code == 201, fired.text
    body = client.post(f"/api/rulesets/{name}/replay", json={"files": guest_rules(10)}).json()
    assert body["replayed"] == 1 and body["changed"] == 1 and body["not_replayable"] == 2
    reasons = sorted(d["reason"] for d in body["not_replayable_decisions"])
    assert "decision_facts_max" in reasons[1] and f"{keep} of {keep + 5}" in reasons[1]
    assert "stateful session" in reasons[0] and sid in reasons[0]


def test_an_async_replay_is_a_job_with_progress(client, recorded):
    name, _facts = recorded
    response = client.post(f"/api/rulesets/{name}/replay", json={"files": guest_rules(10)}, headers=ASYNC)
    assert response.status_code == 202, response.text
    job = response.json()
    assert job["kind"] == "replay" and job["ruleset"] == name
    done = follow(client, response.headers["location"])
    assert done["status"] == "succeeded", done
    assert done["progress"]["stage"] == "replay" and done["progress"]["done"] == done["progress"]["total"] > 0
    sync = client.post(f"/api/rulesets/{name}/replay", json={"files": guest_rules(10)}).json()
    assert done["result"]["changed"] == sync["changed"] > 0
    failed = client.post(f"/api/rulesets/{name}/replay", json={"version": 42}, headers=ASYNC)
    assert failed.status_code == 202
    ended = follow(client, failed.headers["location"])
    assert ended["status"] == "failed" and ended["error"]["status"] == 404


def test_a_running_replay_job_is_cancelled_at_its_next_progress_report(client, api_gateway, recorded):
    from gateway.engine import replay

    name, _facts = recorded
    jobs = api_gateway.jobs
    ids: list[str] = []

    def task(progress):
        def report(done, total, stage):
            if done >= replay.PROGRESS_EVERY and ids:  # the author presses Cancel while it replays
                jobs.cancel(ids[0], by="test")
            progress(done, total, stage)
        return replay.run(api_gateway.engine, api_gateway.decisions, name,
                          replay.ReplayParams(files=guest_rules(10)), on_progress=report)

    job = jobs.submit("replay", name, {}, author="test", task=task)
    ids.append(job["id"])
    ended = follow(client, f"/api/jobs/{job['id']}")
    assert ended["status"] == "cancelled" and "while replay" in ended["error"]["error"]
    assert ended["result"] is None


def test_facts_the_candidate_refuses_are_counted_as_failed(client, recorded):
    name, facts = recorded
    narrower = {"guests.drl": guest_rules(12)["guests.drl"].replace("    age : int\n", "")
                .replace("age < 12", "id == \"x\"").replace("age >= 12", "id != \"x\"")}
    body = client.post(f"/api/rulesets/{name}/replay", json={"files": narrower, "max_changes": 0}).json()
    assert body["failed"] == body["replayed"] == len(facts) and body["changed"] == body["unchanged"] == 0
    assert body["failures"][0]["decision_id"] and "age" in body["failures"][0]["error"]


def test_too_many_synchronous_replays_at_once_are_refused_with_retry_after(client, recorded):
    from gateway.api.routes import replay as route

    name, _facts = recorded
    for _ in range(route.MAX_SYNC_REPLAYS):  # as if that many replays were running now
        assert route.running.acquire(blocking=False)
    try:
        refused = client.post(f"/api/rulesets/{name}/replay", json={"version": 1})
        assert refused.status_code == 429 and refused.headers["retry-after"] == "5"
        assert "respond-async" in refused.json()["error"]
        queued = client.post(f"/api/rulesets/{name}/replay", json={"version": 1}, headers=ASYNC)
        assert queued.status_code == 202  # a job still takes it
        assert follow(client, queued.headers["location"])["status"] == "succeeded"
    finally:
        for _ in range(route.MAX_SYNC_REPLAYS):
            route.running.release()
    assert client.post(f"/api/rulesets/{name}/replay", json={"version": 1}).status_code == 200
