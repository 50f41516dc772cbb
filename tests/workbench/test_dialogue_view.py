"""The workbench's Dialogue view in chromium: a typed sentence and an uploaded WAV (espeak-ng) go
through the real gateway's dialogue rules; what was heard, the intent, the slots, the state and
Pepper's answer are shown."""

from __future__ import annotations

import pytest
from playwright.sync_api import expect

from gateway.dialogue.speech import synthesise
from wb_helpers import PROJECT_ROOT

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def dialogue_rules(gateway) -> None:
    """The shipped dialogue rule set, deployed on the workbench's gateway (seeded with reception only)."""
    folder = PROJECT_ROOT / "rules" / "drl" / "dialogue"
    files = {str(p.relative_to(folder)): p.read_text(encoding="utf-8") for p in folder.rglob("*") if p.is_file()}
    response = gateway.deploy("dialogue", files, "the dialogue rules for the Dialogue view")
    assert response.status_code in (200, 201), response.text


def test_a_typed_then_a_spoken_turn(author_page, dialogue_rules, tmp_path) -> None:
    page = author_page
    page.goto("/workbench#/dialogue")
    expect(page.get_by_test_id("dialogue-menu")).to_contain_text("green tea")
    page.get_by_label("Conversation (table)").fill("table9")
    page.get_by_label("What the customer says").fill("Coffee, please")
    page.get_by_role("button", name="Say").click()
    turn = page.get_by_test_id("dialogue-turn").first
    expect(turn.get_by_test_id("heard")).to_have_text("coffee please")
    expect(turn.get_by_test_id("intent")).to_have_text("Intent: order")
    expect(turn.get_by_test_id("slots")).to_have_text("Drink: coffee · Cups: —")
    expect(turn.get_by_test_id("pepper-says")).to_have_text("How many cups of coffee?")

    wav = tmp_path / "two.wav"
    wav.write_bytes(synthesise("two"))
    page.get_by_test_id("dialogue-wav").set_input_files(str(wav))
    expect(page.get_by_test_id("dialogue-turn")).to_have_count(2)
    spoken = page.get_by_test_id("dialogue-turn").first  # newest first
    expect(spoken.get_by_test_id("heard")).to_have_text("two")
    expect(spoken.get_by_test_id("slots")).to_have_text("Drink: coffee · Cups: 2")
    expect(spoken.get_by_test_id("state")).to_have_text("Conversation: waiting for a yes or no")
    expect(spoken.get_by_test_id("pepper-says")).to_have_text("2 coffees, certainly. Is that right?")


def test_bad_audio_is_explained(author_page, dialogue_rules, tmp_path) -> None:
    page = author_page
    page.goto("/workbench#/dialogue")
    bad = tmp_path / "song.wav"
    bad.write_bytes(b"ID3 not a wav")
    page.get_by_test_id("dialogue-wav").set_input_files(str(bad))
    expect(page.get_by_test_id("dialogue-status")).to_contain_text("not a WAV file")
