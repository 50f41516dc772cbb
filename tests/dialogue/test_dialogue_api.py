"""``POST /api/dialogue/turns`` by text and by espeak-ng audio through the recogniser, bad input
(422 naming the problem), the orders in the Information State, the grammar and Pepper's voice."""

from __future__ import annotations

import base64
import io
import itertools
import wave

import pytest

from gateway.dialogue.speech import synthesise
from gw_testing import wait_for

_ids = itertools.count(1)


def say(client, conversation: str, **body):
    return client.post("/api/dialogue/turns", json={"conversation": conversation, **body})


def spoken(text: str, **kw) -> str:
    return base64.b64encode(synthesise(text, **kw)).decode()


def test_a_text_turn_answers_the_documented_fields(client):
    r = say(client, "api-t1", text="Two green teas, please", table="table1")
    assert r.status_code == 200, r.text
    body = r.json()
    assert {"conversation", "heard", "intent", "slots", "actions", "state", "decision_id"} <= set(body)
    assert body["intent"] == "order" and body["slots"] == {"drink": "green tea", "cups": 2}
    assert [(a["module"], a["params"]) for a in body["actions"]] == \
        [("say", {"robot": "pepper", "text": "2 green teas, certainly. Is that right?"})]
    assert body["state"] == "confirming" and body["heard"] == "two green teas please"


@pytest.mark.parametrize("sentence, intent, slots", [
    ("two green teas please", "order", {"drink": "green tea", "cups": 2}),
    ("can i have a coffee", "order", {"drink": "coffee", "cups": 1}),
    ("three cups of hojicha", "order", {"drink": "hojicha", "cups": 3}),
    ("i would like an orange juice", "order", {"drink": "orange juice", "cups": 1}),
])
def test_an_audio_turn_is_recognised_with_the_grammar(client, sentence, intent, slots):
    r = say(client, f"api-a{next(_ids)}", audio=spoken(sentence))
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["heard"].replace(" an ", " a ") == sentence.replace(" an ", " a ")  # a/an sound alike
    assert body["intent"] == intent and body["slots"] == slots
    assert body["recognition"]["latency_ms"] > 0


def test_a_customer_who_forgets_the_count_is_asked_by_voice(client):
    conv = f"api-v{next(_ids)}"
    first = say(client, conv, audio=spoken("coffee please"), table="table1").json()
    assert first["says"] == ["How many cups of coffee?"]
    second = say(client, conv, audio=spoken("two")).json()
    assert second["slots"] == {"drink": "coffee", "cups": 2} and second["state"] == "confirming"
    third = say(client, conv, audio=spoken("yes")).json()
    assert third["state"] == "ordered"


def _wav(seconds: float, rate: int = 16000, width: int = 2) -> bytes:
    buf = io.BytesIO()
    with wave.open(buf, "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(width)
        w.setframerate(rate)
        w.writeframes(b"\x00" * int(seconds * rate) * width)
    return buf.getvalue()


@pytest.mark.parametrize("audio, problem", [
    (base64.b64encode(b"ID3\x04 this is an mp3").decode(), "not a WAV file"),
    ("", "empty"),
    (base64.b64encode(_wav(0)).decode(), "no samples"),
    (base64.b64encode(_wav(16)).decode(), "at most 15 s"),
    (base64.b64encode(_wav(1, width=1)).decode(), "8-bit"),
    ("%%%not base64", "not base64"),
])
def test_bad_audio_is_422_naming_the_problem(client, audio, problem):
    r = say(client, "api-bad", audio=audio)
    assert r.status_code == 422, r.text
    assert problem in r.json()["error"] and r.json()["field"] == "audio"


def test_text_and_audio_together_or_neither_are_422(client):
    assert say(client, "api-bad", text="coffee", audio=spoken("coffee")).status_code == 422
    r = say(client, "api-bad")
    assert r.status_code == 422 and r.json()["field"] == "text"


def test_a_bad_conversation_id_is_422(client):
    r = say(client, "table 1", text="coffee")
    assert r.status_code == 422 and r.json()["field"] == "conversation"


def test_silence_in_audio_is_not_understood_and_recorded(client, gateway):
    r = say(client, "api-quiet", audio=base64.b64encode(_wav(1)).decode())
    assert r.status_code == 200
    body = r.json()
    assert body["intent"] == "unknown" and body["says"] == ["Sorry, could you say that again?"]
    assert wait_for(lambda: gateway.decisions.get(body["decision_id"]) is not None, 20)


def test_a_completed_order_is_kept_in_the_information_state(client, gateway):
    conv = f"api-o{next(_ids)}"
    say(client, conv, text="one black tea", table="table3")
    done = say(client, conv, text="yes").json()
    assert done["state"] == "ordered"

    def stored():
        gateway.store.flush()
        return [o for o in client.get("/api/dialogue/orders").json()["orders"] if o["conversation"] == conv]

    assert wait_for(stored, 20)
    order = stored()[0]
    assert order["table"] == "table3" and order["drink"] == "black tea" and order["cups"] == 1
    assert order["individual"] == "blackTea" and order["at"]
    assert done["decision_id"] in order["decision_ids"] and len(order["decision_ids"]) == 2


def test_the_grammar_comes_from_the_rules_and_the_menu(client):
    body = client.get("/api/dialogue/grammar").json()
    assert "(no make that <drink>)" in body["jsgf"] and "green teas" in body["jsgf"]
    menu = client.get("/api/dialogue/menu").json()["drinks"]
    assert {"greenTea", "coffee", "matcha"} <= {d["individual"] for d in menu}


def test_pepper_speaks_as_wav(client):
    r = client.post("/api/dialogue/speech", json={"text": "Two green teas, certainly."})
    assert r.status_code == 200 and r.headers["content-type"] == "audio/wav"
    with wave.open(io.BytesIO(r.content)) as w:
        assert w.getnframes() > w.getframerate() // 2  # more than half a second of speech


def test_speech_text_is_never_an_option_and_an_unknown_voice_is_422(client, tmp_path):
    target = tmp_path / "pwn.wav"
    r = client.post("/api/dialogue/speech", json={"text": f"-w {target}"})
    assert r.status_code == 200 and not target.exists()  # spoken, not obeyed
    r = client.post("/api/dialogue/speech", json={"text": "hello", "voice": "nosuchvoice"})
    assert r.status_code == 422 and r.json()["field"] == "voice" and "nosuchvoice" in r.json()["error"]
