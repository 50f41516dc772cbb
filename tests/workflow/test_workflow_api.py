"""REST: list/read/validate/replace/run workflows on a real gateway app (real engine with the
reception rules, simulated robots and humans), and the generated code endpoint."""

from __future__ import annotations

import time

import pytest
from fastapi.testclient import TestClient

from gateway.config import PROJECT_ROOT, Settings

from gw_testing import built_gateway


@pytest.fixture(scope="module")
def client(tmp_path_factory, mongo):
    tmp = tmp_path_factory.mktemp("wfapi")
    settings = Settings.model_validate({
        "data_dir": str(tmp / "var"),
        "engine": {"rules_dir": str(PROJECT_ROOT / "rules" / "drl")},
        "workflows": {"simulate_robots": True, "simulate_humans": True},
    })
    with built_gateway(settings, mongo, tmp) as gateway:
        with TestClient(gateway.app) as test_client:
            yield test_client


def test_list_and_read(client):
    listed = client.get("/api/workflows").json()
    assert [w["business_process"] for w in sorted(listed, key=lambda w: w["business_process"])] == [1, 2, 3, 4, 5, 6, 7, 8]
    body = client.get("/api/workflows/thanking").json()
    assert body["version"] >= 1 and body["text"].startswith("# Business process (7)")
    assert body["workflow_view"]["services"] == [{"name": "farewell", "processes": ["see_off"]}]
    lanes = body["scenario_view"]["lanes"]
    assert lanes[0] == "pepper"
    assert client.get("/api/workflows/nope").status_code == 404
    assert client.get("/api/workflows/schema").json()["title"] == "PRINTEPS workflow"


def test_greeting_fires_the_reception_rules_and_pepper_acts(client):
    run = client.post("/api/workflows/greeting/run", json={"inputs": {}}).json()
    assert run["status"] == "succeeded", run["error"]
    acted = [(s["module"], s["params"]) for s in run["steps"] if s["via"] == "reception_rules"]
    assert ("say", {"robot": "pepper", "text": "Welcome. Two seats?"}) in acted
    assert any(module == "gesture" for module, _ in acted)
    listed = client.get("/api/workflows/runs", params={"workflow": "greeting"}).json()
    assert listed[0]["run_id"] == run["run_id"]
    assert client.get(f"/api/workflows/runs/{run['run_id']}").json()["status"] == "succeeded"


def test_validate_reports_places_and_views(client):
    text = client.get("/api/workflows/thanking").json()["text"]
    good = client.post("/api/workflows/validate", json={"text": text}).json()
    assert good["valid"] and good["scenario_view"]["steps"][0]["id"] == "go_to_door"
    bad = client.post("/api/workflows/validate", json={"text": text.replace("module: say", "module: sing")}).json()
    assert not bad["valid"]
    problem = bad["problems"][0]
    assert problem["path"] == "processes.see_off.steps[1].module" and problem["message"] == "unknown module 'sing'"
    assert text.splitlines()[problem["line"] - 1].strip() == "module: sing".replace("sing", "say")


def test_replace_is_live_for_the_next_run_and_bad_edits_change_nothing(client):
    before = client.get("/api/workflows/thanking").json()
    edited = before["text"].replace("Please come again.", "We hope to see you soon.")
    bad = client.put("/api/workflows/thanking", json={"text": edited.replace("kind: robot", "kind: android")})
    assert bad.status_code == 422
    assert bad.json()["problems"][0]["path"] == "actors.pepper.kind" and bad.json()["problems"][0]["line"] > 0
    stale = client.put("/api/workflows/thanking", json={"text": edited, "base_version": before["version"] - 1})
    assert stale.status_code == 409 and stale.json()["current"] == before["version"]
    wrong_name = client.put("/api/workflows/other", json={"text": edited})
    assert wrong_name.status_code == 422
    ok = client.put("/api/workflows/thanking", json={"text": edited, "base_version": before["version"],
                                                     "comment": "friendlier"})
    assert ok.status_code == 201 and ok.json()["version"] == before["version"] + 1
    run = client.post("/api/workflows/thanking/run", json={}).json()
    assert run["version"] == before["version"] + 1
    assert any(s["params"].get("text") == "Thank you very much. We hope to see you soon." for s in run["steps"])
    versions = client.get("/api/workflows/thanking/versions").json()
    assert versions[-1]["comment"] == "friendlier" and versions[-1]["author"] == "anonymous"
    back = client.post("/api/workflows/thanking/rollback", json={"version": before["version"]})
    assert back.status_code == 201
    assert "Please come again." in client.get("/api/workflows/thanking").json()["text"]


def test_background_run_and_manual_tasks(client):
    client.app.state.gateway.workflows.manual.simulate = False
    try:
        started = client.post("/api/workflows/serving/run", json={"wait": False})
        assert started.status_code == 202
        run_id = started.json()["run_id"]
        deadline = time.monotonic() + 5
        tasks = []
        while not tasks and time.monotonic() < deadline:
            tasks = client.get("/api/workflows/manual").json()
            time.sleep(0.02)
        assert tasks[0]["prompt"] == "Serve the drinks on the pass to table1" and tasks[0]["actor"] == "staff"
        assert client.get(f"/api/workflows/runs/{run_id}").status_code == 202
        assert client.post(f"/api/workflows/manual/{tasks[0]['id']}/done", json={"result": {"by": "Ken"}}).status_code == 200
        assert client.post("/api/workflows/manual/task-0/done", json={}).status_code == 404
        result = None
        while time.monotonic() < deadline + 5:
            response = client.get(f"/api/workflows/runs/{run_id}")
            if response.status_code == 200:
                result = response.json()
                break
            time.sleep(0.02)
        assert result and result["status"] == "succeeded" and result["steps"][0]["output"]["by"] == "Ken"
    finally:
        client.app.state.gateway.workflows.manual.simulate = True


def test_generated_code_endpoint(client):
    response = client.get("/api/workflows/thanking/code")
    assert response.status_code == 200 and response.headers["content-type"].startswith("text/x-python")
    compile(response.text, "thanking.py", "exec")
    assert "def process_see_off(self, v):" in response.text


def test_bad_request_bodies(client):
    assert client.put("/api/workflows/thanking", json={"text": ""}).status_code == 422
    assert client.post("/api/workflows/validate", json={"yaml": "x"}).status_code == 422
    assert client.post("/api/workflows/thanking/run", json={"inputs": []}).status_code == 422
    assert client.post("/api/workflows/missing/run", json={}).status_code == 404
