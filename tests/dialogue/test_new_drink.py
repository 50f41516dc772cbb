"""A drink added through the knowledge API can be ordered at once, by text and by voice — with a
pronunciation spelled out from its letters when the recogniser's dictionary lacks the word."""

from __future__ import annotations

import base64

from gateway.dialogue.speech import synthesise


def test_a_new_beverage_is_ordered_by_text_and_voice(client, gateway):
    before = client.post("/api/dialogue/turns", json={"conversation": "nd-0", "text": "two yuzu lemonades"}).json()
    assert before["intent"] == "order" and before["slots"]["drink"] is None  # not on the menu yet

    r = client.post("/api/knowledge/individuals", json={
        "name": "yuzuLemonade", "class": "Beverage", "values": {"label": "yuzu lemonade"},
        "comment": "summer menu"})
    assert r.status_code == 201, r.text
    assert r.json()["name"] == "yuzuLemonade" and r.json()["version"] >= 2

    text = client.post("/api/dialogue/turns", json={"conversation": "nd-1", "text": "Two yuzu lemonades, please"}).json()
    assert text["slots"] == {"drink": "yuzu lemonade", "cups": 2}
    assert text["says"] == ["2 yuzu lemonades, certainly. Is that right?"]

    audio = base64.b64encode(synthesise("two yuzu lemonades please")).decode()
    voice = client.post("/api/dialogue/turns", json={"conversation": "nd-2", "audio": audio}).json()
    assert voice["heard"] in ("two yuzu lemonades please", "two yuzu lemonade please"), voice  # plural or not: one drink
    assert voice["slots"] == {"drink": "yuzu lemonade", "cups": 2}
    grammar = client.get("/api/dialogue/grammar").json()
    assert "yuzu" in grammar["spelled"]  # not in the dictionary: pronounced from its letters


def test_a_new_individual_is_checked_field_by_field(client):
    cases = [
        ({"name": "greenTea", "class": "Beverage"}, "name", "already"),
        ({"name": "bad name", "class": "Beverage"}, "name", "letter"),
        ({"name": "kombucha", "class": "Drinkable"}, "class", "not a class"),
        ({"name": "kombucha", "class": "Beverage", "values": {"colour": "brown"}}, "values.colour", "not a data property"),
        ({"name": "kombucha", "class": "Cup", "values": {"cupCapacity": "lots"}}, "values.cupCapacity", "not a number"),
        ({"name": "kombucha", "class": "Beverage", "values": {"label": ""}}, "values.label", "non-empty"),
    ]
    for body, field, words in cases:
        r = client.post("/api/knowledge/individuals", json=body)
        assert r.status_code == 422, (body, r.text)
        assert r.json()["field"] == field and words in r.json()["error"], r.json()
    assert client.get("/api/knowledge/individuals/kombucha").status_code == 404  # nothing was added
