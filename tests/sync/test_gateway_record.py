"""One gateway, one decision record, knowledge and mappings as data: decisions from every origin
(REST, KIE, stream, ROS, workflow) are in the Information State and survive a restart; mappings
are checked against the message type; export/import round-trips through a folder."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from fastapi.testclient import TestClient

from gateway.config import PROJECT_ROOT, Settings

from gw_testing import open_test_store, short_lived_jvm

ENTRANCE = "http://printeps.org/cafe/entrance"
RECEPTION_FACTS = [{"type": "Entrance", "id": "entrance", "number_of_customers": 1},
                   {"type": "Customer", "id": "a", "entrance": "entrance", "age": 30, "gender": "male", "distance": 2.0},
                   {"type": "Robot", "id": "pepper", "position": "entrance"}]


def settings_in(tmp: Path, **extra) -> Settings:
    return Settings.model_validate({"data_dir": str(tmp / "var"), "workflows": {"simulate_robots": True,
                                                                               "simulate_humans": True}, **extra})


def approaching_party(t0_ms: int = 10_000) -> list[dict]:
    """Entrance messages of two people walking up to the entrance, one per second."""
    out = []
    for i, d in enumerate([5.0, 4.0, 3.0, 2.0, 1.8, 1.8]):
        out.append({"stream": ENTRANCE, "timestamp": t0_ms + 1000 * i, "message": {
            "id": f"e{i}", "number_of_customers": 2, "customers": [
                {"id": "p1", "distance": d, "age": 34, "gender": "female"},
                {"id": "p2", "distance": d + 0.05, "age": 36, "gender": "female"}]}})
    return out


def test_decisions_from_every_origin_are_recorded_and_survive_a_restart(tmp_path, mongo):
    """REST, KIE, stream and workflow decisions (no ROS needed: the ROS origin has its own test)."""
    from gateway.app import build_gateway

    settings = settings_in(tmp_path)
    store = open_test_store(mongo, tmp_path)
    try:
        gateway = build_gateway(settings, store=store, ros=False, warm_up=False)
        try:
            http = TestClient(gateway.app)
            rest = http.post("/api/rulesets/reception/fire", json={"facts": RECEPTION_FACTS},
                             headers={"traceparent": "00-4bf92f3577b34da6a3ce929d0e0e4736-00f067aa0ba902b7-01"})
            assert rest.status_code == 200
            kie = http.post("/kie-server/services/rest/server/containers/instances/reception", json={"commands": [
                {"insert": {"object": {"Customer": {"id": "k", "entrance": "entrance", "age": 8}}}},
                {"insert": {"object": {"Entrance": {"id": "entrance", "number_of_customers": 1}}}},
                {"fire-all-rules": {}}]})
            assert kie.json()["type"] == "SUCCESS", kie.text
            kie_decision = next(r["value"] for r in kie.json()["result"]["execution-results"]["results"]
                                if r["key"] == "decision-id")
            for message in approaching_party():
                assert http.post("/api/streams", json=message).status_code == 200
            run = http.post("/api/workflows/greeting/run", json={"inputs": {}})
            assert run.status_code == 200, run.text
            assert gateway.store.flush()
        finally:
            gateway.close()
        # a new process on the same Information State answers for all of them
        again = build_gateway(settings, store=store, ros=False, warm_up=False)
        try:
            http = TestClient(again.app)
            page = http.get("/api/decisions", params={"limit": 100}).json()
            origins = {d["origin"] for d in page["decisions"]}
            # the greeting workflow's first step always fires the reception rules
            assert {"rest", "kie", "stream", "workflow"} <= origins, origins
            workflow = http.get("/api/decisions", params={"origin": "workflow"}).json()["decisions"]
            assert workflow and workflow[0]["ruleset"] == "reception", workflow
            one = http.get(f"/api/decisions/{rest.json()['decision_id']}").json()
            assert one["correlation_id"] == "4bf92f3577b34da6a3ce929d0e0e4736"
            assert http.get(f"/api/decisions/{kie_decision}").json()["origin"] == "kie"
            stream = http.get("/api/decisions", params={"origin": "stream"}).json()["decisions"]
            assert stream and stream[0]["ruleset"] == "reception" and stream[0]["correlation_id"].startswith(
                "CustomerDetectionQuery@")
            customers = {f["id"] for f in stream[0]["facts"] if f["type"] == "Customer"}
            assert customers == {"p1", "p2"}
            assert {f["age"] for f in stream[0]["facts"] if f["type"] == "Customer"} == {34, 36}  # from the stream
            by_rule = http.get("/api/decisions", params={"rule": stream[0]["fired"][0]}).json()["decisions"]
            assert stream[0]["decision_id"] in {d["decision_id"] for d in by_rule}
            first = http.get("/api/decisions", params={"limit": 1}).json()
            second = http.get("/api/decisions", params={"limit": 1, "cursor": first["next_cursor"]}).json()
            assert first["decisions"][0]["decision_id"] > second["decisions"][0]["decision_id"]  # newest first
        finally:
            again.close()
    finally:
        store.close()


@pytest.mark.ros
def test_ros_decisions_are_recorded_with_their_request_id_and_survive_a_restart(tmp_path, mongo):
    from printeps_interfaces.srv import FireBusinessRules
    from rclpy.node import Node

    from gateway.app import build_gateway
    from gateway.ros.runtime import RosRuntime

    settings = settings_in(tmp_path)
    settings.ros.domain_id = 77
    store = open_test_store(mongo, tmp_path)
    try:
        gateway = build_gateway(settings, store=store, ros=True, warm_up=False)
        try:
            with RosRuntime(domain_id=77) as rt:
                client = rt.make(Node, "caller").create_client(FireBusinessRules, "fire_business_rules")
                assert client.wait_for_service(timeout_sec=15)
                ros = client.call(FireBusinessRules.Request(ruleset="reception", facts_json=json.dumps(RECEPTION_FACTS),
                                                            request_id="ros-req"), timeout_sec=10)
            assert ros.success
            assert gateway.store.flush()
        finally:
            gateway.close()
        again = build_gateway(settings, store=store, ros=False, warm_up=False)
        try:
            http = TestClient(again.app)
            recorded = http.get(f"/api/decisions/{ros.decision_id}").json()
            assert (recorded["origin"], recorded["correlation_id"]) == ("ros", "ros-req")
        finally:
            again.close()
    finally:
        store.close()


@pytest.fixture(scope="module")
def gateway(tmp_path_factory, mongo):
    from gw_testing import built_gateway

    tmp = tmp_path_factory.mktemp("record")
    with built_gateway(settings_in(tmp), mongo, tmp) as gw:
        yield gw


SEED_PATTERNS = ("rules/drl/**/*", "workflows/*.yaml", "ontology/*.ttl", "ontology/*.swrl", "ontology/queries/*",
                 "ontology/mappings/*.yaml")


def test_export_writes_the_seed_layout_and_import_of_it_changes_nothing(gateway, tmp_path):
    """Issue 32: on a gateway seeded from the repository, ``export`` writes exactly the seed files —
    the same names (``workflows/1_greeting.yaml``, ``ontology/queries/customer_detection.rq``) and
    bytes — and importing them reports every item unchanged. Before, it wrote ``greeting.yaml`` and
    ``CustomerDetectionQuery.rq`` and re-dumped the YAML sidecars."""
    from gateway.runtime.transfer import export_to, import_from, seed_folders

    out = tmp_path / "out"
    written = sorted(export_to(gateway.catalog, out, seed_folders(gateway.settings)))
    seeds = sorted({str(p.relative_to(PROJECT_ROOT)) for pattern in SEED_PATTERNS for p in PROJECT_ROOT.glob(pattern)
                    if p.is_file()})
    assert written == seeds
    for rel in seeds:
        assert (out / rel).read_bytes() == (PROJECT_ROOT / rel).read_bytes(), rel
    report = import_from(gateway, out, author="git", comment="nothing changed")
    assert len(report) == 4 + 2 + 8 + 3 + 2  # rule sets, knowledge, workflows, mappings, queries
    assert all(outcome.startswith("unchanged") for _, outcome in report), report
    # exported again into the copy: the same files, none added under another name
    assert sorted(export_to(gateway.catalog, out)) == seeds
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()) == seeds


def test_mappings_are_data_checked_against_the_message_type(gateway):
    pytest.importorskip("printeps_interfaces")
    http = TestClient(gateway.app)
    names = {m["name"]: m for m in http.get("/api/mappings").json()}
    assert names["entrance"]["message_type"] == "printeps_interfaces/msg/Entrance"
    spec = http.get("/api/mappings/entrance").json()["spec"]
    wrong = json.loads(json.dumps(spec))
    wrong["children"]["customers"]["fields"]["height"] = "printeps:height"
    r = http.put("/api/mappings/entrance", json={"spec": wrong})
    assert r.status_code == 422
    assert r.json()["where"] == "mapping.children.customers.fields.height"
    assert "printeps_interfaces/msg/Customer has no field 'height'" in r.json()["error"]
    misnamed = json.loads(json.dumps(spec))
    misnamed["children"]["has_customers"] = misnamed["children"].pop("customers")
    r = http.put("/api/mappings/entrance", json={"spec": misnamed})
    assert r.status_code == 422 and "Entrance has no field 'has_customers'" in r.json()["error"]
    assert http.post("/api/mappings/validate", json={"spec": {"subject": 3}}).json()["ok"] is False
    # a good change is a new version, live at once
    renamed = json.loads(json.dumps(spec))
    renamed["children"]["customers"]["fields"]["gender"] = "printeps:sex"
    r = http.put("/api/mappings/entrance", json={"spec": renamed, "comment": "sex, not gender"})
    assert r.status_code == 201 and r.json()["version"] == 2
    preview = http.post("/api/mappings/entrance/preview", json={"message": {
        "id": "e1", "customers": [{"id": "c1", "distance": 2.5, "gender": "female"}]}, "timestamp": 5}).json()
    assert any(t[1].endswith("/sex>") or t[1].endswith("sex") for t in preview["triples"]), preview
    assert [v["version"] for v in http.get("/api/mappings/entrance/versions").json()] == [1, 2]
    assert http.put("/api/mappings/entrance", json={"spec": spec}).status_code == 201


def test_export_then_import_round_trips_and_bad_items_are_refused(gateway, tmp_path):
    from gateway.runtime.transfer import export_to, import_from

    written = export_to(gateway.catalog, tmp_path / "out")
    assert "rules/drl/reception/reception.dslr" in written and "workflows/greeting.yaml" in written
    assert "ontology/teahouse.ttl" in written and "ontology/queries/CustomerDetectionQuery.rq" in written
    assert "ontology/mappings/entrance.yaml" in written
    report = dict(import_from(gateway, tmp_path / "out", author="git", comment="unchanged"))
    assert all(outcome.startswith("unchanged") for outcome in report.values()), report
    dslr = tmp_path / "out" / "rules" / "drl" / "reception" / "reception.dslr"
    dslr.write_text(dslr.read_text().replace("Welcome. Two seats?", "Two of you, welcome!"))
    # the rule set's own scenarios still expect the old greeting: refused like a deploy, with the place
    report = dict(import_from(gateway, tmp_path / "out", author="git", comment="rules only"))
    assert report["rule set reception"].startswith("failed: tests/reception.yaml:"), report
    scenarios = tmp_path / "out" / "rules" / "drl" / "reception" / "tests" / "reception.yaml"
    scenarios.write_text(scenarios.read_text().replace("Welcome. Two seats?", "Two of you, welcome!"))
    workflow = tmp_path / "out" / "workflows" / "thanking.yaml"
    workflow.write_text(workflow.read_text().replace("kind: robot", "kind: android"))
    report = dict(import_from(gateway, tmp_path / "out", author="git", comment="from a branch"))
    assert report["rule set reception"].startswith("deployed v"), report
    assert report["workflow thanking.yaml"].startswith("failed: ") and "actors.pepper.kind" in report["workflow thanking.yaml"]
    assert "Two of you, welcome!" in gateway.engine.current("reception").files["reception.dslr"]
    assert gateway.engine.current("reception").info.author == "git"
    ontology = tmp_path / "out" / "ontology"
    (ontology / "draft.owl").write_text("<rdf:RDF/>")  # two ontologies: which one is meant is not guessed
    report = dict(import_from(gateway, tmp_path / "out", author="git", comment="two ontologies"))
    assert report["ontology draft.owl, teahouse.ttl"] == f"failed: {ontology} holds 2 ontology files: keep one"
    assert report["swrl teahouse.swrl"].startswith("unchanged v"), report


def test_export_and_import_commands_join_a_running_gateway(tmp_path):
    """``printeps export`` / ``import`` on the data dir of a running gateway use its database, and
    the running gateway follows the import at once."""
    import os
    import time

    import httpx

    from gateway.serve import free_port

    config = tmp_path / "printeps.yaml"
    config.write_text(yaml.safe_dump({"data_dir": str(tmp_path / "var"), "streams": {"queries_dir": None}}))
    env = short_lived_jvm({k: v for k, v in os.environ.items() if k != "MONGO_URI"})
    port = free_port()
    serve = subprocess.Popen([sys.executable, "-m", "gateway.cli", "serve", "--no-ros", "--port", str(port), "--config",
                              str(config)], env=env, cwd=PROJECT_ROOT, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 180
        while True:
            assert serve.poll() is None and time.monotonic() < deadline
            try:
                if httpx.get(f"http://127.0.0.1:{port}/health", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.3)

        def cli(*args: str) -> subprocess.CompletedProcess:
            return subprocess.run([sys.executable, "-m", "gateway.cli", *args, "--config", str(config)], env=env,
                                  cwd=PROJECT_ROOT, capture_output=True, text=True, timeout=300)

        out = tmp_path / "repo"
        exported = cli("export", str(out))
        assert exported.returncode == 0, exported.stderr
        assert (out / "rules" / "drl" / "reception" / "reception.dslr").exists()
        for changed in ("reception.dslr", "tests/reception.yaml"):  # the rules and their scenarios
            path = out / "rules" / "drl" / "reception" / changed
            path.write_text(path.read_text().replace("Welcome. Two seats?", "Welcome, you two!"))
        imported = cli("import", str(out), "--comment", "from git")
        assert imported.returncode == 0, imported.stdout + imported.stderr
        assert "rule set reception: deployed v2" in imported.stdout
        # copies: the module's RECEPTION_FACTS are shared with other tests (test_decision_format)
        facts = {"facts": [dict(RECEPTION_FACTS[0], number_of_customers=2), dict(RECEPTION_FACTS[1], id="b"),
                           dict(RECEPTION_FACTS[1], id="c"), *RECEPTION_FACTS[2:]]}

        def says() -> str:
            answer = httpx.post(f"http://127.0.0.1:{port}/api/rulesets/reception/fire", json=facts, timeout=10).json()
            return " ".join(a["params"].get("text", "") for a in answer["actions"])

        deadline = time.monotonic() + 10
        while "Welcome, you two!" not in says():
            assert time.monotonic() < deadline, says()
            time.sleep(0.1)
    finally:
        serve.terminate()
        serve.wait(timeout=60)
