"""SWRL + OWL reasoning with Pellet warm in the gateway JVM; fresh inference on every call."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import jpype
import pytest
from fastapi.testclient import TestClient

from gateway.ontology import Reasoner, ReasonerError

ROOT = Path(__file__).resolve().parents[2]
P = "http://printeps.org/cafe/entrance/"


@pytest.fixture()
def files(tmp_path) -> tuple[Path, Path]:
    onto, swrl = tmp_path / "teahouse.ttl", tmp_path / "teahouse.swrl"
    shutil.copy(ROOT / "ontology" / "teahouse.ttl", onto)
    shutil.copy(ROOT / "ontology" / "teahouse.swrl", swrl)
    return onto, swrl


@pytest.fixture()
def reasoner(files) -> Reasoner:
    return Reasoner.from_files(*files)


def group_at_entrance(size: int, ages: tuple[int, ...] = ()) -> dict:
    customers = [f"c{i}" for i in range(len(ages))]
    return {"individuals": [
        {"id": "group1", "types": ["Group"], "properties": {"numberOfCustomers": size, "hasCustomer": customers}},
        {"id": "entrance1", "properties": {"hasGroup": "group1"}},
        *({"id": c, "types": ["Customer"], "properties": {"age": a}} for c, a in zip(customers, ages)),
    ]}


def inferred(result: dict, predicate: str) -> dict[str, object]:
    return {f["subject"].rsplit("/", 1)[-1]: f["object"] for f in result["inferred"] if f["predicate"] == P + predicate}


def test_the_papers_greeting_rule(reasoner):
    result = reasoner.reason(group_at_entrance(2))
    assert inferred(result, "greeting") == {"pepper1": "Welcome. Two seats?"}
    assert inferred(result, "servedTo") == {"greetingAtEntrance1": P + "group1"}
    assert jpype.isJVMStarted()  # Pellet ran inside this process's JVM


def test_no_stale_inferences_between_calls(reasoner):
    assert inferred(reasoner.reason(group_at_entrance(2)), "greeting") == {"pepper1": "Welcome. Two seats?"}
    assert inferred(reasoner.reason(group_at_entrance(3)), "greeting") == {"pepper1": "Welcome. Three seats?"}
    assert inferred(reasoner.reason({"individuals": []}), "greeting") == {}


def test_child_seat_threshold_is_an_editable_swrl_rule(reasoner, files):
    ages = (5, 8, 40)
    assert inferred(reasoner.reason(group_at_entrance(3, ages)), "needsChildSeat") == {"c0": True}
    children = {t["individual"].rsplit("/", 1)[-1] for t in reasoner.reason(group_at_entrance(3, ages))["types"]
                if t["class"] == P + "Child"}
    assert children == {"c0", "c1"}
    _, swrl = files  # Table 2 #15: change the threshold, no restart
    swrl.write_text(swrl.read_text().replace("lessThan(?a, 7)", "lessThan(?a, 10)"))
    assert inferred(reasoner.reason(group_at_entrance(3, ages)), "needsChildSeat") == {"c0": True, "c1": True}


def test_beverage_quantity_rule(reasoner, files):
    cup = {"individuals": [{"id": "cup1", "types": ["Cup"], "properties": {"cupCapacity": 200}}]}
    assert inferred(reasoner.reason(cup), "pourQuantity") == {"cup1": 160.0}
    _, swrl = files  # Table 2 #16: pour slightly less
    swrl.write_text(swrl.read_text().replace("?capacity, 0.8)", "?capacity, 0.7)"))
    assert inferred(reasoner.reason(cup), "pourQuantity") == {"cup1": 140.0}


def test_turtle_input(reasoner):
    ttl = f"""@prefix printeps: <{P}> .
    printeps:g9 a printeps:Group ; printeps:numberOfCustomers 1 .
    printeps:entrance1 printeps:hasGroup printeps:g9 ."""
    assert inferred(reasoner.reason(ttl), "greeting") == {"pepper1": "Welcome. One seat?"}


@pytest.mark.parametrize("data, where", [
    ({"individuals": [{"id": "x", "types": ["Nope"]}]}, "individuals[0].types[0]"),
    ({"individuals": [{"id": "x", "properties": {"colour": 1}}]}, "individuals[0].properties.colour"),
    ({"individuals": [{"id": "x", "properties": {"age": [1, {"a": 1}]}}]}, "individuals[0].properties.age[1]"),
    ({"individuals": [{"id": "bad name"}]}, "individuals[0].id"),
    ({"people": []}, "body"),
    ("@prefix x: <http://x/> . x:a x:b", "body"),
])
def test_bad_input_names_the_place(reasoner, data, where):
    with pytest.raises(ReasonerError) as info:
        reasoner.reason(data)
    assert info.value.where == where and info.value.status == 422


def test_a_broken_rule_names_file_and_line(reasoner, files):
    _, swrl = files
    swrl.write_text("# comment\nCustomer(?c) -> Nope(?c)\n")
    with pytest.raises(ReasonerError) as info:
        reasoner.reason({"individuals": []})
    assert info.value.where.endswith("teahouse.swrl:2")


def test_drools_still_fires_next_to_pellet(reasoner, tmp_path):
    from gateway.config import Settings
    from gateway.engine import Engine

    reasoner.reason(group_at_entrance(2))
    engine = Engine(Settings(data_dir=str(tmp_path / "d"), engine={"rules_dir": str(tmp_path / "r")}))
    drl = ("package t; import org.printeps.gateway.Actions; global Actions actions;\n"
           "declare Ping id: String end\nrule r when Ping() then actions.say(\"pepper\", \"pong\"); end\n")
    engine.deploy("t", {"t.drl": drl}, author="test")
    result = engine.fire("t", [{"type": "Ping", "id": "1"}])
    assert [a["params"]["text"] for a in result.to_dict()["actions"]] == ["pong"]


def test_post_reason_endpoint(files, mongo, tmp_path):
    from gateway.config import Settings
    from gw_testing import built_gateway

    onto, _ = files
    settings = Settings.model_validate({"data_dir": str(tmp_path / "d"), "engine": {"rules_dir": str(tmp_path / "r")},
                                        "streams": {"knowledge_dir": str(onto.parent),
                                                    "queries_dir": None}})
    with built_gateway(settings, mongo, tmp_path) as gateway:
        client = TestClient(gateway.app)
        r = client.post("/api/reason", json=group_at_entrance(2))
        assert r.status_code == 200 and inferred(r.json(), "greeting") == {"pepper1": "Welcome. Two seats?"}
        r = client.post("/api/reason", content="printeps:x a", headers={"content-type": "text/turtle"})
        assert r.status_code == 422 and r.json()["where"] == "body"
        r = client.post("/api/reason", json={"individuals": [{"id": "x", "types": ["Nope"]}]})
        assert r.status_code == 422 and r.json()["where"] == "individuals[0].types[0]"


def test_what_the_texts_alone_infer_is_kept_on_disk_for_the_next_process(files, tmp_path, monkeypatch):
    """A process starting on texts another process has reasoned over reads the answer from the
    cache folder instead of running Pellet (~3 CPU-s of every gateway start); a damaged copy is
    reasoned again and rewritten, and other texts are not answered from it."""
    from gateway.ontology import reasoner as module

    monkeypatch.setenv("PRINTEPS_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(module, "_plain", {})
    onto, swrl = files
    first = Reasoner.from_files(onto, swrl).reason(None)
    assert first["inferred"], "the teahouse ontology infers something on its own"
    (copy,) = (tmp_path / "cache" / "reasoner").glob("*.json")

    pellet_runs: list[int] = []
    real_pellet = Reasoner._pellet
    monkeypatch.setattr(Reasoner, "_pellet", lambda self, *a: pellet_runs.append(1) or real_pellet(self, *a))
    monkeypatch.setattr(module, "_plain", {})  # as a new process
    again = Reasoner.from_files(onto, swrl).reason(None)
    assert (again["inferred"], again["types"], pellet_runs) == (first["inferred"], first["types"], [])

    copy.write_text("{not json")
    monkeypatch.setattr(module, "_plain", {})
    damaged = Reasoner.from_files(onto, swrl).reason(None)
    assert (damaged["inferred"], damaged["types"], pellet_runs) == (first["inferred"], first["types"], [1])
    assert json.loads(copy.read_text())["inferred"] == first["inferred"]

    swrl.write_text("")  # other texts (no SWRL rules: fewer inferences) are reasoned over and kept apart
    monkeypatch.setattr(module, "_plain", {})
    other = Reasoner.from_files(onto, swrl).reason(None)
    assert pellet_runs == [1, 1] and other["inferred"] != first["inferred"]
    assert len(list((tmp_path / "cache" / "reasoner").glob("*.json"))) == 2
