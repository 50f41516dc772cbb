"""Each run is recorded in the Information State (a real SecantusDB process, reached through pymongo)."""

from __future__ import annotations

from gateway.config import Settings
from gateway.workflow.service import RUNS_COLLECTION, build_service


def test_runs_and_steps_are_recorded(store, tmp_path):
    settings = Settings.model_validate({"data_dir": str(tmp_path / "var"),
                                        "workflows": {"simulate_robots": True, "simulate_humans": True}})
    service = build_service(settings, store=store)
    service.registry.seed(settings.workflows.source_dir)  # what the composition root does for a gateway
    service.registry.load()
    try:
        result = service.run("thanking")
    finally:
        service.close()
    assert result.status == "succeeded"
    assert store.flush()
    finished = store.query(RUNS_COLLECTION, type="printeps/workflow_run_finished", filters={"run_id": result.run_id})
    assert len(finished) == 1 and finished[0]["status"] == "succeeded" and finished[0]["workflow"] == "thanking"
    steps = store.query(RUNS_COLLECTION, type="printeps/workflow_step", filters={"run_id": result.run_id},
                        newest_first=False)
    assert [s["step_id"] for s in steps] == ["go_to_door", "thank", "bow", "back_to_counter"]
    assert steps[1]["params"]["text"] == "Thank you very much. Please come again."
    assert steps[0]["_meta"]["inserted_by"] == "workflow_executor"
