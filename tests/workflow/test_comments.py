"""A visual save keeps the author's comments where they stood (gateway.workflow.comments)."""

from __future__ import annotations

from pathlib import Path

import pytest

from gateway.workflow.comments import split_comment
from gateway.workflow.render import read_document, to_yaml

TEAHOUSE = Path(__file__).resolve().parents[2] / "workflows"

COMMENTED = """# Business process (7): thanking customers upon their departure.
workflow: thanking
title: Thanking customers upon their departure   # shown in the workbench
inputs:
  party: {size: 2}
modules:
  # the robot's services
  say: {kind: ros_service, actor: pepper, service: /pepper/speak, type: printeps_interfaces/srv/Speak}
  move_to: {kind: ros_service, actor: pepper, service: /pepper/move_to, type: printeps_interfaces/srv/MoveTo}
actors:
  pepper: {kind: robot, label: Pepper}
processes:
  see_off:
    steps:
      # walk them out first
      - id: go_to_door
        module: move_to
        with: {location: entrance}  # the door, not the counter
      # then the words

      - id: thank
        module: say
        with: {text: "Thank you # very much"}
      - id: back
        module: move_to
        with: {location: counter}
services:
  farewell:
    processes: [see_off]
route:
  start: customers leave
  services: [farewell]
  end: gone
"""


def test_comments_stay_where_they_stood_after_a_visual_save():
    document = read_document(COMMENTED)
    document["processes"]["see_off"]["steps"][1]["with"]["text"] = "Thanks!"
    written = to_yaml(document, COMMENTED)
    assert read_document(written) == document
    assert "title: Thanking customers upon their departure  # shown in the workbench\n" in written
    assert "modules:\n  # the robot's services\n  say: {" in written
    assert "    steps:\n      # walk them out first\n      - id: go_to_door\n" in written
    assert "with: {location: entrance}  # the door, not the counter\n" in written
    assert "      # then the words\n      - id: thank\n" in written
    assert written.startswith("# Business process (7)")


def test_a_comment_goes_with_its_step_and_follows_it_when_steps_move():
    document = read_document(COMMENTED)
    steps = document["processes"]["see_off"]["steps"]
    steps[0], steps[1] = steps[1], steps[0]  # thank first, then go to the door
    written = to_yaml(document, COMMENTED)
    assert written.index("# then the words") < written.index("- id: thank") < written.index("# walk them out first")
    del steps[0]  # the thank step is removed: its comment with it
    written = to_yaml(document, COMMENTED)
    assert "# then the words" not in written and "# walk them out first" in written


def test_lines_of_a_block_text_are_text_even_when_they_start_with_a_hash():
    text = COMMENTED.replace('        with: {text: "Thank you # very much"}\n',
                             "        with:\n          text: |\n            # not a comment\n            Thank you.\n", 1)
    document = read_document(text)
    assert document["processes"]["see_off"]["steps"][1]["with"]["text"] == "# not a comment\nThank you.\n"
    written = to_yaml(document, text)
    assert read_document(written) == document
    assert [line for line in written.splitlines() if line.strip() == "# not a comment"] == []


def test_a_hash_inside_quotes_is_text_not_a_comment():
    assert split_comment('  with: {text: "Thank you # very much"}') == ('  with: {text: "Thank you # very much"}', "")
    assert split_comment("  a: 1 # note") == ("  a: 1", "# note")
    assert split_comment("  url: http://x/#frag") == ("  url: http://x/#frag", "")


@pytest.mark.parametrize("path", sorted(TEAHOUSE.glob("*.yaml")), ids=lambda p: p.name)
def test_a_save_without_changes_keeps_every_comment(path):
    text = path.read_text(encoding="utf-8")
    written = to_yaml(read_document(text), text)
    comments = [line.strip() for line in text.splitlines() if line.strip().startswith("#")]
    assert [line.strip() for line in written.splitlines() if line.strip().startswith("#")] == comments
