"""Table 2 of the teahouse paper, suggestions 1-16, done live on one running gateway over REST:
for each, the robots' behaviour before, the edit submitted, and the new behaviour after — with no
restart and no failed request. Scenarios build on each other in the paper's order."""

from __future__ import annotations

import pytest

from agile_harness import TABLES, OwnerClient, apply, behaviour, running_gateway, scenarios

pytestmark = pytest.mark.slow  # the sixteen Table-2 changes one after another on one gateway: a story

SCENARIOS = scenarios()


@pytest.fixture(scope="module")
def gateway(tmp_path_factory) -> OwnerClient:
    with running_gateway(tmp_path_factory.mktemp("agile")) as gw:
        yield gw


def test_all_sixteen_implementable_suggestions_have_a_scenario():
    assert [s.id for s in SCENARIOS] == list(range(1, 17))
    assert {s.category for s in SCENARIOS} == {"WF", "BR", "Onto", "SWRL", "WF+BR"}


@pytest.mark.parametrize("scenario", SCENARIOS, ids=[f"{s.id}-{s.category}" for s in SCENARIOS])
def test_suggestion_goes_live(gateway, scenario):
    measured = apply(gateway, scenario)
    assert measured.ok, measured.failed_requests
    assert measured.before != measured.after
    assert scenario.expect(measured.after) and not scenario.expect(measured.before)
    assert measured.lines_changed > 0 and measured.chars_changed > 0


def test_all_changes_hold_together_afterwards(gateway):
    seat = behaviour(gateway.run("show_to_seat"))
    assert seat == ["pepper move_to: (2.50, 0.00)",
                    "pepper say: I will show you to your table. Please follow me.",
                    "pepper gesture: point to the table",
                    "pepper move_to: (3.20, 2.00)",
                    "pepper say: Here is your table. Please have a seat."]
    greeting = behaviour(gateway.run("greeting", {"tables": TABLES}))
    assert "pepper gesture: deep bow with open arms" in greeting
    assert any("blanket" in line for line in greeting) and any("free tables" in line for line in greeting)
    versions = gateway.http.get("/api/workflows/show_to_seat/versions").json()
    assert [v["comment"] for v in versions[1:]] == ["Table 2: workflow edit"] * 3
