"""The take_order workflow runs the dialogue: Pepper asks, a (simulated) customer answers, the
dialogue rules confirm, and the order the dialogue completed goes on to the next steps."""

from __future__ import annotations


def test_take_order_runs_the_dialogue(gateway):
    result = gateway.workflows.run("take_order", {"table": {"id": "table4", "x": 4.0, "y": 2.0},
                                                  "customer_says": ["coffee please", "three", "yes"]})
    assert result.status == "succeeded", result.error
    order = next(s for s in result.steps if s.step_id == "ask_order").output
    assert order["drink"] == "coffee" and order["cups"] == 3 and order["table"] == "table4"
    assert len(order["decision_ids"]) == 3  # one decision per turn
    said = [c["params"]["text"] for c in gateway.workflows.robots.calls if c["step"] == "confirm_order"]
    assert said[-1] == "3 coffees, certainly. I will bring them to your table."


def test_no_order_within_the_time_is_a_clear_failure(gateway):
    import pytest

    with pytest.raises(LookupError, match="no order within 0.5 s"):
        gateway.dialogue.take_order("table6", customer_says=["to read the league"], timeout_s=0.5)


def test_a_conversation_that_ends_without_an_order_fails_at_once(gateway):
    import threading

    import pytest

    outcome: dict = {}

    def wait() -> None:
        try:
            gateway.dialogue.take_order("table7", customer_says=["coffee"], timeout_s=60)
        except LookupError as exc:
            outcome["error"] = str(exc)

    waiter = threading.Thread(target=wait)
    waiter.start()
    from gw_testing import wait_for

    assert wait_for(lambda: any(c["conversation"] == "table7" for c in gateway.dialogue.conversations()), 20)
    gateway.dialogue.silence("table7", 61)
    waiter.join(10)
    assert outcome.get("error") == "conversation table7 ended without an order"
