"""Multi-turn conversations through the dialogue service on the real engine: slots across turns,
the missing slot asked for, yes/no, a correction, words nobody understands, silence."""

from __future__ import annotations

import itertools
import time

import pytest

from gateway.dialogue.service import DialogueRefused
from gw_testing import wait_for

_ids = itertools.count(1)


@pytest.fixture
def conv() -> str:
    return f"c{next(_ids)}"


def says(answer: dict) -> list[str]:
    return answer["says"]


def test_one_sentence_with_both_slots_is_confirmed_then_ordered(gateway, conv):
    d = gateway.dialogue
    first = d.turn(conv, text="Can I have two green teas, please?", table="table1")
    assert first["heard"] == "can i have two green teas please"
    assert first["intent"] == "order"
    assert first["slots"] == {"drink": "green tea", "cups": 2}
    assert first["state"] == "confirming"
    assert says(first) == ["2 green teas, certainly. Is that right?"]
    assert first["decision_id"]
    done = d.turn(conv, text="yes please")
    assert done["intent"] == "yes" and done["state"] == "ordered"
    assert says(done) == ["Thank you. Your green teas will be ready soon."]
    order = next(a for a in done["actions"] if a["module"] == "order")
    assert order["params"] == {"conversation": conv, "table": "table1", "drink": "green tea", "cups": 2}


def test_a_forgotten_count_is_asked_for(gateway, conv):
    d = gateway.dialogue
    first = d.turn(conv, text="I'd like a matcha... no wait, just matcha", table="table2")
    # "a matcha" says one: the count is filled; a sentence with only the drink leaves it open
    assert first["slots"]["drink"] == "matcha"
    second = d.turn(f"{conv}b", text="coffee please", table="table2")
    assert second["state"] == "ordering" and second["slots"] == {"drink": "coffee", "cups": None}
    assert says(second) == ["How many cups of coffee?"]
    third = d.turn(f"{conv}b", text="three")
    assert third["intent"] == "order" and third["slots"] == {"drink": "coffee", "cups": 3}
    assert says(third) == ["3 coffees, certainly. Is that right?"]


def test_no_make_that_coffee_corrects_the_drink_and_keeps_the_count(gateway, conv):
    d = gateway.dialogue
    d.turn(conv, text="two green teas")
    corrected = d.turn(conv, text="No, make that coffee.")
    assert corrected["intent"] == "correct"
    assert corrected["slots"] == {"drink": "coffee", "cups": 2}
    assert says(corrected) == ["2 coffees, certainly. Is that right?"]


def test_no_starts_the_order_again(gateway, conv):
    d = gateway.dialogue
    d.turn(conv, text="one black tea")
    again = d.turn(conv, text="no")
    assert again["intent"] == "no" and again["slots"] == {"drink": None, "cups": None}
    assert says(again) == ["What would you like to drink?"]


def test_words_nobody_understands_get_sorry_and_are_recorded(gateway, conv):
    d = gateway.dialogue
    d.turn(conv, text="hojicha")
    answer = d.turn(conv, text="to read the league")
    assert answer["intent"] == "unknown"
    assert says(answer) == ["Sorry, could you say that again?"]
    assert answer["slots"] == {"drink": "hojicha", "cups": None}  # nothing lost
    assert wait_for(lambda: (gateway.decisions.get(answer["decision_id"]) or {}).get("origin") == "dialogue", 20)
    recorded = gateway.decisions.get(answer["decision_id"])
    assert recorded["context"]["heard"] == "to read the league" and recorded["context"]["intent"] == "unknown"


def test_silence_ends_the_conversation_and_the_next_turn_starts_anew(gateway, conv):
    d = gateway.dialogue
    d.turn(conv, text="coffee")
    assert d.silence(conv, 20)["state"] == "ordering"  # the rules wait for 60 s
    ended = d.silence(conv, 61)
    assert ended["state"] == "ended"
    assert says(ended) == ["Please call me when you are ready to order."]
    assert all(c["conversation"] != conv for c in d.conversations())
    fresh = d.turn(conv, text="two")
    assert fresh["slots"] == {"drink": None, "cups": 2} and fresh["turn"] == 1


def test_the_watcher_tells_a_quiet_conversation(gateway, conv):
    d = gateway.dialogue
    d.turn(conv, text="coffee")
    answers = d.check_silences(now=time.time() + 61)
    assert any(a["conversation"] == conv and a["state"] == "ended" for a in answers)


def test_a_conversation_idle_too_long_is_closed_even_if_the_rules_keep_it(gateway, conv):
    d = gateway.dialogue
    d.turn(conv, text="coffee")
    d.check_silences(now=time.time() + d.settings.max_idle_s + 1)
    assert all(c["conversation"] != conv for c in d.conversations())
    assert d.finished[conv]["state"] == "ended"


@pytest.mark.parametrize("kwargs, field", [
    ({}, "text"), ({"text": "x", "audio": b"RIFF"}, "text"), ({"text": "x" * 501}, "text"),
])
def test_bad_turns_name_the_field(gateway, kwargs, field):
    with pytest.raises(DialogueRefused) as refused:
        gateway.dialogue.turn("c-bad", **kwargs)
    assert refused.value.field == field


def test_a_bad_conversation_id_is_refused(gateway):
    with pytest.raises(DialogueRefused) as refused:
        gateway.dialogue.turn("no spaces", text="coffee")
    assert refused.value.field == "conversation"
