"""The visual editor's server side without a gateway: the palette from ROS interfaces, robots and
workflows; the document written back as YAML; the wait's seconds checked per field."""

from __future__ import annotations

import pytest

from gateway.config import PROJECT_ROOT
from gateway.workflow.loader import WorkflowInvalid, load, parse
from gateway.workflow.palette import build_palette, read_interfaces, robots_of
from gateway.workflow.render import leading_comments, read_document, to_yaml

TEAHOUSE = PROJECT_ROOT / "workflows"
INTERFACES = read_interfaces(PROJECT_ROOT / "ros")


def test_interfaces_are_read_from_the_srv_files():
    assert INTERFACES["printeps_interfaces/srv/Speak"].request == [("robot", "string"), ("text", "string")]
    move = INTERFACES["printeps_interfaces/srv/MoveTo"]
    assert [name for name, _ in move.request] == ["robot", "location", "x", "y"]
    assert "named location" in move.comments["location"]


def test_robots_are_the_configured_ones_and_those_the_workflows_drive():
    workflows = [load(path) for path in sorted(TEAHOUSE.glob("*.yaml"))]
    robots = {r.name: r for r in robots_of({"pepper": "/pepper"}, INTERFACES, workflows)}
    assert robots["pepper"].configured and set(robots["pepper"].services) == {"speak", "gesture", "move_to"}
    assert robots["hsr"].services == {"gesture": "printeps_interfaces/srv/Gesture",
                                      "move_to": "printeps_interfaces/srv/MoveTo"}
    assert not robots["hsr"].configured and robots["hsr"].namespace == "/hsr"


def test_palette_entries_have_typed_parameters():
    palette = build_palette(configured_robots={"pepper": "/pepper"}, interfaces=INTERFACES, workflows=[],
                            rulesets=["reception", "seat_info"], ontology_values={"pepper1.robotToHumanDistance": 1.0})
    entries = {e["id"]: e for e in palette["entries"]}
    assert set(entries) == {"pepper.gesture", "pepper.move_to", "pepper.speak", "fire_rules", "ontology_value",
                            "wait", "manual", "branch", "set", "dialogue"}
    assert entries["pepper.speak"]["module_name"] == "say"
    ruleset = entries["fire_rules"]["module_params"][0]
    assert ruleset["choices"] == ["reception", "seat_info"] and ruleset["default"] == "reception"
    assert entries["ontology_value"]["params"][0]["choices"] == ["pepper1.robotToHumanDistance"]
    assert palette["ontology_values"] == [{"name": "pepper1.robotToHumanDistance", "value": 1.0}]


@pytest.mark.parametrize("path", sorted(TEAHOUSE.glob("*.yaml")), ids=lambda p: p.name)
def test_documents_are_written_back_as_equivalent_yaml(path):
    text = path.read_text(encoding="utf-8")
    document = read_document(text)
    written = to_yaml(document, text)
    assert read_document(written) == document
    assert written.startswith(leading_comments(text)) and leading_comments(text).startswith("# ")
    assert parse(written).name == document["workflow"]
    assert "- id: " in written and "- {id:" not in written  # steps stay blocks, one key a line


def test_a_wait_that_is_not_a_number_is_named_by_its_field():
    text = (TEAHOUSE / "3_take_order.yaml").read_text(encoding="utf-8")
    document = read_document(text)
    document["modules"]["pause"] = {"kind": "wait", "params": {"seconds": "soon"}}
    document["processes"]["take_order"]["steps"].insert(1, {"id": "let_them_finish", "module": "pause"})
    with pytest.raises(WorkflowInvalid) as bad:
        parse(to_yaml(document))
    assert [p.path for p in bad.value.problems] == ["modules.pause.params.seconds"]
    document["processes"]["take_order"]["steps"][1]["with"] = {"seconds": "${input.pause}"}
    assert parse(to_yaml(document)).modules["pause"].kind == "wait"  # a template is checked when it runs
