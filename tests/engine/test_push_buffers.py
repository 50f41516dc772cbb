"""StatefulSession.push through the shared 64 KiB buffers (and the String paths around them), the
fact encoder (orjson with the strict fallback) and the answer decoder."""

from __future__ import annotations

import dataclasses
import datetime
import decimal
import enum
import json
import threading
import uuid

import pytest

from gateway.engine import Engine, FactError, FireResult, RuleRuntimeError, RunawayRules
from gateway.engine.results import BUFFER_BYTES, decode_result, encode_facts, encode_facts_bytes, raise_refusal

from engine_samples import engine_with

PUSH_DRL = """package org.printeps.pushtest;
import org.printeps.gateway.Actions;
global Actions actions;

declare Item
    id: String
    text: String
end

declare Tick
    @role(event)
    @expires(1s)
    seq: int
    text: String
end

rule "tick"
when
    $t: Tick()
then
    actions.say("nao", "tick " + $t.getSeq());
end

rule "item"
when
    $i: Item()
then
    actions.say("pepper", "item " + $i.getId());
end
"""


@pytest.fixture(scope="module")
def push_engine(tmp_path_factory) -> Engine:
    return engine_with(tmp_path_factory.mktemp("push"), "push", {"rules.drl": PUSH_DRL})


@pytest.fixture()
def session(push_engine):
    opened = push_engine.open_session("push")
    yield opened
    opened.close()


def tick(seq: int, text: str = "") -> list[dict]:
    return [{"type": "Tick", "seq": seq, "text": text}]


def answer_size(result: FireResult) -> int:
    """Roughly what the Java answer weighed (what had to fit the 64 KiB output buffer)."""
    return len(json.dumps({"actions": result.actions, "fired": result.fired, "facts": result.facts}).encode())


# ---------------------------------------------------------------------------------- push sizes


@pytest.mark.timeout(60)
def test_push_of_facts_larger_than_the_buffer(session):
    items = [{"type": "Item", "id": f"i{k}", "text": "t" * 50} for k in range(2_000)]
    assert len(encode_facts_bytes(items, 100_000)) > BUFFER_BYTES  # takes the String path in
    result = session.push(items)
    assert result.fire_count == 2_000
    assert sorted(a["params"]["text"] for a in result.actions) == sorted(f"item i{k}" for k in range(2_000))
    assert answer_size(result) > BUFFER_BYTES  # and the answer came back through the overflow
    assert session.fact_count == 2_000
    # the buffered path still works after it
    small = session.push(tick(1))
    assert [a["params"]["text"] for a in small.actions] == ["tick 1"]


@pytest.mark.timeout(60)
@pytest.mark.parametrize("delta", [-1, 0, 1])
def test_push_around_the_buffer_size(session, delta):
    empty = len(encode_facts_bytes([{"type": "Item", "id": "edge", "text": ""}], 10))
    text = "e" * (BUFFER_BYTES + delta - empty)
    facts = [{"type": "Item", "id": "edge", "text": text}]
    assert len(encode_facts_bytes(facts, 10)) == BUFFER_BYTES + delta
    result = session.push(facts)
    assert [a["params"]["text"] for a in result.actions] == ["item edge"]
    assert result.fired[0]["facts"][0]["text"] == text
    again = session.push(tick(7, "small"))  # whichever path the last one took, the next is clean
    assert [a["params"]["text"] for a in again.actions] == ["tick 7"]


def compact_answer_size(result: FireResult) -> int:
    """The exact size of the Java answer for a push without return_facts (it writes compact JSON)."""
    answer = {"ok": True, "fireCount": result.fire_count, "actions": result.actions, "fired": result.fired}
    return len(json.dumps(answer, separators=(",", ":"), ensure_ascii=False).encode())


@pytest.mark.timeout(60)
def test_answers_around_the_buffer_size(session):
    probe_text = "p" * 100
    probe = session.push([{"type": "Item", "id": "o0", "text": probe_text}])
    overhead = compact_answer_size(probe) - len(probe_text)  # the same for every id of two characters
    for k, delta in enumerate([-2, -1, 0, 1, 2], start=1):
        text = "q" * (BUFFER_BYTES + delta - overhead)
        facts = [{"type": "Item", "id": f"o{k}", "text": text}]
        assert len(encode_facts_bytes(facts, 10)) <= BUFFER_BYTES  # the buffered path in
        result = session.push(facts)
        assert compact_answer_size(result) == BUFFER_BYTES + delta  # fits the buffer exactly, or just not
        assert [a["params"]["text"] for a in result.actions] == [f"item o{k}"]
        assert result.fired[0]["facts"][0] == {"type": "Item", "id": f"o{k}", "text": text}
        small = session.push(tick(k))
        assert [a["params"]["text"] for a in small.actions] == [f"tick {k}"]


@pytest.mark.timeout(60)
def test_small_push_with_an_answer_larger_than_the_buffer(session):
    session.insert([{"type": "Item", "id": f"k{k}", "text": "f" * 60} for k in range(1_500)])
    session.fire()  # the items' own firings are done
    for round_ in range(3):  # big, small, big, small...: no stale overflow in between
        big = session.push(tick(round_), return_facts=True)
        assert [a["params"]["text"] for a in big.actions] == [f"tick {round_}"]
        assert sum(1 for f in big.facts if f["type"] == "Item") == 1_500
        assert {f["id"] for f in big.facts if f["type"] == "Item"} == {f"k{k}" for k in range(1_500)}
        assert answer_size(big) > BUFFER_BYTES
        small = session.push(tick(100 + round_))
        assert [a["params"]["text"] for a in small.actions] == [f"tick {100 + round_}"]
        assert small.facts == []


@pytest.mark.timeout(60)
def test_many_actions_in_one_answer(session):
    items = [{"type": "Item", "id": f"a{k:04d}"} for k in range(1_200)]  # small in, ~100 KB of actions out
    assert len(encode_facts_bytes(items, 100_000)) < BUFFER_BYTES
    result = session.push(items)
    assert len(result.actions) == result.fire_count == 1_200
    assert {a["params"]["text"] for a in result.actions} == {f"item a{k:04d}" for k in range(1_200)}
    assert answer_size(result) > BUFFER_BYTES


@pytest.mark.timeout(60)
def test_concurrent_pushes_get_their_own_answers(session):
    threads_n, per_thread = 4, 250
    failures: list[str] = []
    answered: list[int] = []
    lock = threading.Lock()
    start = threading.Barrier(threads_n)

    def worker(t: int) -> None:
        start.wait()
        try:
            for k in range(per_thread):
                seq = t * 100_000 + k
                big = k % 25 == 0  # String path in, overflow out
                text = chr(ord("a") + t) * (70_000 if big else k % 40)
                result = session.push(tick(seq, text))
                texts = [a["params"]["text"] for a in result.actions]
                matched = result.fired[0]["facts"][0]
                if texts != [f"tick {seq}"] or matched != {"type": "Tick", "seq": seq, "text": text}:
                    failures.append(f"thread {t} push {seq} got {texts} {str(result.fired)[:200]}")
                with lock:
                    answered.append(seq)
        except Exception as exc:  # noqa: BLE001 - reported below
            failures.append(f"thread {t}: {type(exc).__name__}: {exc}")

    threads = [threading.Thread(target=worker, args=(t,)) for t in range(threads_n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(50)
    assert not any(t.is_alive() for t in threads)
    assert failures == []
    assert sorted(answered) == sorted(t * 100_000 + k for t in range(threads_n) for k in range(per_thread))


@pytest.mark.timeout(60)
def test_pushes_and_a_feed_into_the_same_session(session):
    fed: list[int] = []
    feed = session.feed(lambda r: fed.append(int(r.actions[0]["params"]["text"].split()[1])))
    failures: list[str] = []

    def pusher(t: int) -> None:
        try:
            for k in range(200):
                seq = 1_000_000 * (t + 1) + k
                texts = [a["params"]["text"] for a in session.push(tick(seq, "p" * (k % 7))).actions]
                if texts != [f"tick {seq}"]:
                    failures.append(f"push {seq} got {texts}")
        except Exception as exc:  # noqa: BLE001
            failures.append(f"{type(exc).__name__}: {exc}")

    threads = [threading.Thread(target=pusher, args=(t,)) for t in range(2)]
    for t in threads:
        t.start()
    for seq in range(1_000):
        feed.submit(tick(seq))
    for t in threads:
        t.join(50)
    assert feed.flush(30)
    feed.close()
    assert failures == []
    assert fed == list(range(1_000))


# ---------------------------------------------------------------------------------- encoding

SAMPLE = [
    {"type": "Customer", "id": "c1", "age": 30, "gender": "female", "distance": 1.5, "vip": True},
    {"type": "Customer", "id": "c2", "age": -4, "distance": 0.0, "tags": ["a", "b"], "meta": {"k": [1, 2, {"z": 3}]}},
    {"type": "Group", "id": "g1", "size": 2, "big": 2**62, "empty": "", "list": []},
]


def test_encoded_facts_are_what_the_strict_encoder_writes():
    data = encode_facts_bytes(SAMPLE, 100)
    assert isinstance(data, bytes)
    assert data == json.dumps(SAMPLE, separators=(",", ":"), allow_nan=False).encode()
    assert encode_facts(SAMPLE, 100) == data.decode("utf-8")
    assert json.loads(data) == SAMPLE
    assert encode_facts_bytes(tuple(SAMPLE), 100) == data  # a tuple is a list of facts too


@pytest.mark.parametrize(
    "facts",
    [
        [{"type": "X", "text": "日本語 ünïcödé 🙂 \"quoted\" \\ back\nslash \u2028"}],
        [{"type": "X", "f": 1e300, "g": -1e-300, "h": 0.1, "i": -0.0, "j": 123456789.123456789}],
        [{"type": "X", "huge": 2**70, "neg": -(2**70)}],  # orjson refuses >64-bit ints: the strict one writes them
        [{"type": "X", "deep": {"a": {"b": {"c": [[["x"]]]}}}}],
        [],
        [{}],
    ],
)
def test_encoded_facts_round_trip(facts):
    data = encode_facts_bytes(facts, 100)
    assert json.loads(data) == facts
    assert json.loads(encode_facts(facts, 100)) == facts


def test_none_values_are_kept():
    facts = [{"type": "X", "a": None, "b": [None, 1], "c": {"d": None}, "e": "nullable null"}]
    data = encode_facts_bytes(facts, 10)
    assert json.loads(data) == facts
    assert json.loads(encode_facts_bytes([{"type": "X", "e": "null"}], 10)) == [{"type": "X", "e": "null"}]


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), float("-inf")])
def test_nan_and_infinity_are_refused_naming_fact_and_field(bad):
    facts = [{"type": "X", "id": "ok"}, {"type": "Customer", "id": "c7", "distance": bad}]
    with pytest.raises(FactError) as err:
        encode_facts_bytes(facts, 10)
    problem = err.value.errors[0]
    assert (problem["index"], problem["field"], problem["type"], problem["id"]) == (1, "distance", "Customer", "c7")
    assert "NaN or infinity" in problem["message"]
    assert "fact 1" in str(err.value)
    with pytest.raises(FactError) as nested:
        encode_facts_bytes([{"type": "X"}, {"type": "X"}, {"type": "X", "values": [1.0, {"v": bad}]}], 10)
    assert (nested.value.errors[0]["index"], nested.value.errors[0]["field"]) == (2, "values")


def test_non_string_keys_become_strings_like_json_dumps():
    fact = {"type": "X", 7: "seven", 2.5: "two and a half", True: "yes", None: "nothing"}
    data = encode_facts_bytes([fact], 10)
    assert json.loads(data) == json.loads(json.dumps([fact]))
    assert json.loads(data) == [{"type": "X", "7": "seven", "2.5": "two and a half", "true": "yes", "null": "nothing"}]
    assert json.loads(encode_facts_bytes([{"type": "X", 1: "one"}], 10)) == [{"type": "X", "1": "one"}]


@dataclasses.dataclass
class Point:
    x: int


@pytest.mark.parametrize(
    "value",
    [
        datetime.datetime(2024, 1, 2, 3, 4, 5),
        datetime.date(2024, 1, 2),
        datetime.time(3, 4),
        {1, 2},
        frozenset({"a"}),
        b"bytes",
        bytearray(b"x"),
        decimal.Decimal("1.5"),
        complex(1, 2),
        object(),
        Point(1),
    ],
    ids=lambda v: type(v).__name__,
)
def test_values_json_cannot_carry_are_refused_naming_the_field(value):
    with pytest.raises(FactError) as err:
        encode_facts_bytes([{"type": "X"}, {"type": "Event", "id": "e1", "when": value}], 10)
    problem = err.value.errors[0]
    assert (problem["index"], problem["field"]) == (1, "when")
    assert type(value).__name__ in problem["message"]


def _nested(depth: int, kind: str) -> object:
    nested: object = 1 if kind == "list" else {}
    for _ in range(depth):
        nested = [nested] if kind == "list" else {"d": nested}
    return nested


@pytest.mark.parametrize("kind", ["list", "dict"])
def test_moderate_nesting_encodes_exactly(kind):
    facts = [{"type": "X", "deep": _nested(300, kind)}]
    assert json.loads(encode_facts_bytes(facts, 10)) == facts


@pytest.mark.parametrize("kind", ["list", "dict"])
def test_nesting_too_deep_for_json_is_refused_naming_the_fact_and_field(kind):
    facts = [{"type": "Ok", "id": "a"}, {"type": "X", "id": "b", "deep": _nested(5_000, kind)}]
    with pytest.raises(FactError) as err:
        encode_facts_bytes(facts, 10)
    problem = err.value.errors[0]
    assert (problem["index"], problem["id"], problem["field"]) == (1, "b", "deep")
    assert "nested too deeply" in problem["message"]


def test_300_deep_nesting_behaves_like_the_strict_encoder():
    nested: object = 1
    for _ in range(300):
        nested = [nested]
    facts = [{"type": "X", "deep": nested}]
    strict = json.dumps(facts, separators=(",", ":"), allow_nan=False)  # the standard encoder manages 300
    assert encode_facts_bytes(facts, 10) == strict.encode()


def test_circular_facts_are_refused():
    loop: dict = {"type": "X"}
    loop["self"] = loop
    with pytest.raises(FactError):
        encode_facts_bytes([loop], 10)
    cycle: list = []
    cycle.append(cycle)
    with pytest.raises(FactError):
        encode_facts_bytes([{"type": "X", "c": cycle}], 10)


@pytest.mark.parametrize(
    "facts",
    [{"type": "X"}, "[]", b"[]", None, 5, {1, 2}, (f for f in [{"type": "X"}])],
    ids=["dict", "str", "bytes", "None", "int", "set", "generator"],
)
def test_facts_must_be_a_list(facts):
    with pytest.raises(FactError, match="must be a list") as err:
        encode_facts_bytes(facts, 10)
    assert err.value.errors[0]["index"] == -1


def test_too_many_facts():
    with pytest.raises(FactError, match="too many facts: 11"):
        encode_facts_bytes([{"type": "X"}] * 11, 10)
    assert json.loads(encode_facts_bytes([{"type": "X"}] * 10, 10)) == [{"type": "X"}] * 10


class Colour(enum.Enum):
    RED = "red"


@pytest.mark.parametrize(("value", "written"), [(uuid.UUID(int=1), str(uuid.UUID(int=1))), (Colour.RED, "red")],
                         ids=["UUID", "Enum"])
def test_uuid_and_enum_values_are_written_the_same_on_both_paths(value, written):
    """orjson writes a UUID as its text and an Enum as its value; the strict encoder (taken when a
    None or the text "null" is in the facts) must write them the same, not refuse them."""
    fast = json.loads(encode_facts_bytes([{"type": "X", "v": value}], 10))
    strict = json.loads(encode_facts_bytes([{"type": "X", "v": value, "w": None}], 10))
    assert fast == [{"type": "X", "v": written}]
    assert strict == [{"type": "X", "v": written, "w": None}]


# ---------------------------------------------------------------------------------- decoding

ANSWER = ('{"ok":true,"fireCount":2,"actions":[{"module":"say","params":{"robot":"pepper","text":"こんにちは"},'
          '"rule":"greet"}],"fired":[{"rule":"greet","facts":[{"type":"C","id":"c1"}]},{"rule":"other"}],'
          '"facts":[{"type":"C","id":"c1"}]}')
NOTHING = '{"ok":true,"fireCount":0,"actions":[],"fired":[]}'


def _forms(text: str) -> list:
    return [text, text.encode("utf-8"), bytearray(text.encode("utf-8"))]


def test_decode_result_accepts_str_bytes_and_bytearray():
    decoded = [decode_result(form, "rs", 3, 1.25) for form in _forms(ANSWER)]
    first = decoded[0]
    assert first.actions[0]["params"]["text"] == "こんにちは"
    assert first.fire_count == 2 and [f["rule"] for f in first.fired] == ["greet", "other"]
    assert first.facts == [{"type": "C", "id": "c1"}]
    assert (first.ruleset, first.version, first.duration_ms) == ("rs", 3, 1.25)
    assert all(d == first for d in decoded)

    empty = [decode_result(form, "rs", 3, 0.5) for form in _forms(NOTHING)]
    assert all(e == FireResult("rs", 3, [], [], [], 0, 0.5) for e in empty)
    spaced = '{"ok": true, "fireCount": 0, "actions": [], "fired": []}'  # not the fast path's exact text
    assert all(decode_result(f, "rs", 3, 0.5) == empty[0] for f in _forms(spaced))


@pytest.mark.parametrize(
    "answer, error",
    [
        ('{"ok":false,"kind":"facts","errors":[{"index":0,"type":"C","id":null,"field":"age","message":"bad"}],'
         '"errorCount":1}', FactError),
        ('{"ok":false,"kind":"runaway","limit":50,"counts":{"loop":49,"x":1}}', RunawayRules),
        ('{"ok":false,"kind":"runtime","rule":"boom","message":"NumberFormatException: x"}', RuleRuntimeError),
        ('{"ok":false,"kind":"runtime","rule":null,"message":"IllegalStateException: gone"}', RuleRuntimeError),
    ],
)
def test_decode_result_raises_refusals_for_every_form(answer, error):
    for form in _forms(answer):
        with pytest.raises(error) as err:
            decode_result(form, "rs", 1, 0.0)
        if error is FactError:
            assert err.value.errors[0]["field"] == "age" and err.value.total == 1
        elif error is RunawayRules:
            assert err.value.limit == 50 and err.value.counts == {"loop": 49, "x": 1}
        else:
            assert err.value.rule == json.loads(answer)["rule"]
    with pytest.raises(error):
        raise_refusal(json.loads(answer))


@pytest.mark.timeout(60)
def test_real_answers_decode_the_same_in_every_form(session):
    result = session.push([{"type": "Item", "id": "r1", "text": "ü"}], return_facts=True)
    again = [decode_result(form, result.ruleset, result.version, 0.0)
             for form in _forms(json.dumps({"ok": True, "fireCount": result.fire_count, "actions": result.actions,
                                            "fired": result.fired, "facts": result.facts}, ensure_ascii=False))]
    assert all(a.actions == result.actions and a.fired == result.fired and a.facts == result.facts for a in again)
