"""Unit tests of the HTTP edge's plain parts: KIE translation, auth, JSON limits, diffs, the decision record's document."""

from __future__ import annotations


import pytest

from gateway.engine.errors import FactError
from fastapi.security import HTTPAuthorizationCredentials, HTTPBasicCredentials

from gateway.api.kie import batch as kie_batch
from gateway.api.auth import Authenticator
from gateway.api.errors import ApiError
from gateway.api.jsonio import BadBody, json_depth_ok, parse_json
from gateway.api.limits import BodyLimit
from gateway.api.routes.rulesets import facts_from_body, file_diffs
from gateway.config import ApiSettings, load_settings
from gw_testing import run_async


def test_tokens_and_users_parse_from_env_strings(monkeypatch):
    monkeypatch.setenv("PRINTEPS_TOKENS", "t1:author:alice, t2:caller:bob")
    monkeypatch.setenv("PRINTEPS_BASIC_USERS", "kie:pw:caller")
    api = load_settings().api
    assert api.tokens["t1"].name == "alice" and api.tokens["t1"].role == "author"
    assert api.tokens["t2"].role == "caller"
    assert api.basic_users["kie"].password == "pw"
    assert api.is_open is False


def test_bad_token_string_names_the_entry():
    with pytest.raises(ValueError, match="entry 2"):
        ApiSettings.model_validate({"tokens": "a:author:x,broken"})
    with pytest.raises(ValueError):
        ApiSettings.model_validate({"tokens": "a:boss:x"})


def test_open_by_default_and_closable():
    assert ApiSettings().is_open
    assert not ApiSettings(open=False).is_open
    assert ApiSettings.model_validate({"tokens": "a:author:x", "open": True}).is_open


def _bearer(token: str) -> HTTPAuthorizationCredentials:
    return HTTPAuthorizationCredentials(scheme="Bearer", credentials=token)


def test_authenticator_roles():
    auth = Authenticator(ApiSettings.model_validate({"tokens": "ta:author:alice,tc:caller:bob",
                                                     "basic_users": "kie:pw:caller"}))
    assert auth.check("author", _bearer("ta")).name == "alice"
    assert auth.check("caller", _bearer("ta")).role == "author"  # author may do what caller may
    assert auth.check("caller", _bearer("tc")).name == "bob"
    with pytest.raises(ApiError) as e:
        auth.check("author", _bearer("tc"))
    assert e.value.status == 403
    with pytest.raises(ApiError) as e:
        auth.check("developer", _bearer("ta"))  # an author is no developer
    assert e.value.status == 403
    for bad in (_bearer("nope"), None):
        with pytest.raises(ApiError) as e:
            auth.check("caller", bad)
        assert e.value.status == 401 and "WWW-Authenticate" in e.value.headers
    assert auth.check("caller", None, HTTPBasicCredentials(username="kie", password="pw")).via == "basic"
    with pytest.raises(ApiError) as e:
        auth.check("caller", None, HTTPBasicCredentials(username="kie", password="wrong"))
    assert e.value.status == 401


def test_a_developer_may_do_what_an_author_may():
    auth = Authenticator(ApiSettings.model_validate({"tokens": "td:developer:dora", "basic_users": "k:pw:developer"}))
    assert auth.check("author", _bearer("td")).role == "developer"
    assert auth.check("caller", None, HTTPBasicCredentials(username="k", password="pw")).role == "developer"
    with pytest.raises(ValueError, match="role"):
        ApiSettings.model_validate({"tokens": "tx:admin:eve"})


def test_open_mode_is_anonymous_developer_but_checks_presented_tokens():
    auth = Authenticator(ApiSettings())  # open mode stays on this machine (printeps serve), where code runs anyway
    assert auth.check("developer", None).to_dict() == {"name": "anonymous", "role": "developer", "auth": "open"}
    with pytest.raises(ApiError):
        auth.check("caller", _bearer("made-up"))


def test_json_depth_and_errors():
    assert json_depth_ok({"a": [1, {"b": 2}]}, 3)
    assert not json_depth_ok({"a": [1, {"b": 2}]}, 2)
    deep = "[" * 100 + "]" * 100
    with pytest.raises(BadBody, match="deeper"):
        parse_json(deep.encode(), 64)
    with pytest.raises(BadBody) as e:
        parse_json(b'{"facts": [1,]}', 64)
    assert e.value.status == 400 and "line" in e.value.extra
    with pytest.raises(BadBody, match="empty"):
        parse_json(b"  ", 64)


def test_fire_body_errors_name_the_fact():
    assert facts_from_body({"facts": [{"type": "A"}]}, 10) == [{"type": "A"}]
    with pytest.raises(FactError) as e:  # the engine's own shape: 422 kind "facts"
        facts_from_body({"facts": [{"type": "A"}, {"age": 3}, 7]}, 10)
    assert e.value.kind == "facts" and str(e.value).endswith("(and 1 more error)")
    assert [(x["index"], x["field"]) for x in e.value.errors] == [(1, "type"), (2, None)]
    for body in ([], {"fact": []}, {"facts": {}}, {"facts": [], "x": 1}):
        with pytest.raises(ApiError):
            facts_from_body(body, 10)
    with pytest.raises(ApiError, match="too many"):
        facts_from_body({"facts": [{"type": "A"}] * 3}, 2)


def test_file_diffs_only_changed_files():
    out = file_diffs({"a.drl": "x\ny\n", "b.drl": "same\n"}, {"a.drl": "x\nz\n", "b.drl": "same\n", "c.drl": "new\n"}, 1, 2)
    assert set(out) == {"a.drl", "c.drl"}
    assert "-y" in out["a.drl"] and "+z" in out["a.drl"] and "v1/a.drl" in out["a.drl"]


def test_kie_command_parsing():
    batch = kie_batch.parse_batch({"lookup": None, "commands": [
        {"insert": {"object": {"org.x.Customer": {"id": "c1"}}, "out-identifier": "c"}},
        {"fire-all-rules": ""},
        {"delete": {"fact-handle": {kie_batch.FACT_HANDLE: {"external-form": "0:1:2:3:4:DEFAULT:NON_TRAIT:x"}}}},
        {"modify": {"fact-handle": "0:1:2", "setters": {"accessor": "age", "value": "3"}}},
        {"advance-session-time": {"amount": 2, "unit": "SECONDS"}},
        {"get-session-time": {}},
    ]})
    assert [s.name for s in batch.steps] == ["insert", "fire-all-rules", "delete", "modify", "advance-session-time",
                                             "get-session-time"]
    assert batch.commands == [
        {"op": "insert", "facts": [{"type": "org.x.Customer", "id": "c1"}], "ep": "DEFAULT", "out": "c", "ret": True},
        {"op": "fire", "max": -1, "out": ""},  # a bare string is the out-identifier, as KIE Server reads it
        {"op": "delete", "handle": "0:1:2:3:4:DEFAULT:NON_TRAIT:x"},
        {"op": "modify", "handle": "0:1:2", "set": [["age", "3"]], "whole": True},  # KIE modify: every rule re-evaluated
        {"op": "advance", "ms": 2000, "out": "session-advancecurrenttime"},
        {"op": "get_time", "out": "session-currenttime"},
    ]
    assert kie_batch.parse_batch({"fire-all-rules": {"max": 5}}).commands == [{"op": "fire", "max": 5, "out": None}]
    for bad, msg in (([], "JSON object"), ({"commands": []}, "no commands"),
                     ({"commands": [{"start-process": {}}]}, "command 0 .start-process.: processes are not supported"),
                     ({"commands": [{"fire-all-rules": {}}, {"insert": 3}]}, "command 1 .insert.: its arguments must be an object"),
                     ({"commands": [{"fire-all-rules": {"max": "lots"}}]}, "'max' must be an integer"),
                     ({"commands": [{"retract": {}}]}, "'fact-handle' is required"),
                     ({"commands": [{"dance": {}}]}, "unknown command 'dance'")):
        with pytest.raises(kie_batch.BatchError, match=msg):
            kie_batch.parse_batch(bad)


def test_kie_fact_translation_round_trip():
    assert kie_batch.fact_from_kie({"org.printeps.reception.Customer": {"id": "c1", "age": 3}}, 0, "insert") == {
        "type": "org.printeps.reception.Customer", "id": "c1", "age": 3}
    assert kie_batch.fact_from_kie({"containedObject": {"@class": "Person", "age": 2}}, 0, "insert-elements", 1) == {
        "type": "Person", "age": 2}
    marshal = kie_batch.Marshal({"Customer": "org.printeps.reception.Customer"})
    assert marshal.object({"type": "Customer", "id": "c1", "home": {"type": "Address", "city": "Tokyo"}}) == {
        "org.printeps.reception.Customer": {"id": "c1", "home": {"city": "Tokyo"}}}
    assert kie_batch.unwrap_typed({"java.lang.Integer": 18}) == 18
    assert kie_batch.unwrap_typed({"plain": 1}) == {"plain": 1}
    with pytest.raises(kie_batch.BatchError, match="reserved"):
        kie_batch.fact_from_kie({"a.B": {"type": "x"}}, 0, "insert")
    with pytest.raises(kie_batch.BatchError, match="object 2"):
        kie_batch.fact_from_kie({"a.B": 1, "c.D": {}}, 0, "insert-elements", 2)
    assert marshal.handle("0:1")[kie_batch.FACT_HANDLE] == {"external-form": "0:1"}


def _run_asgi(app, headers, chunks):
    sent = []

    async def receive():
        if chunks:
            return {"type": "http.request", "body": chunks.pop(0), "more_body": bool(chunks)}
        return {"type": "http.disconnect"}

    async def send(message):
        sent.append(message)

    scope = {"type": "http", "headers": headers}
    run_async(app(scope, receive, send))
    return sent


def test_body_limit_declared_and_streamed():
    async def echo(scope, receive, send):
        while True:
            message = await receive()
            if not message.get("more_body"):
                break
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"ok"})

    limited = BodyLimit(echo, max_bytes=10)
    assert _run_asgi(limited, [(b"content-length", b"11")], [b"x" * 11])[0]["status"] == 413
    assert _run_asgi(limited, [], [b"x" * 6, b"x" * 6])[0]["status"] == 413
    assert _run_asgi(limited, [(b"content-length", b"zz")], [b""])[0]["status"] == 400
    assert _run_asgi(limited, [], [b"x" * 5])[0]["status"] == 200


def test_jvm_options_come_from_the_environment_split_like_a_shell(monkeypatch):
    """How a soak (or an operator) turns on the JVM's native memory tracking without a file."""
    monkeypatch.setenv("PRINTEPS_JVM_OPTIONS", "-XX:NativeMemoryTracking=summary  '-Dprinteps.note=two words'")
    assert load_settings().jvm.extra_options == ["-XX:NativeMemoryTracking=summary", "-Dprinteps.note=two words"]
    monkeypatch.delenv("PRINTEPS_JVM_OPTIONS")
    assert load_settings().jvm.extra_options == []


def test_the_start_up_warm_up_is_a_setting_the_suite_turns_off_for_its_processes(monkeypatch, mongo, tmp_path):
    """`serve` warms the JIT up at start (engine.process_warm_up); the gateway processes the tests
    start skip it through PRINTEPS_PROCESS_WARM_UP=0 (tests/conftest.py): ~2 CPU-s and ~7 s of
    shutdown each."""
    from gw_testing import built_gateway

    monkeypatch.setenv("PRINTEPS_PROCESS_WARM_UP", "0")
    off = load_settings()
    assert off.engine.process_warm_up is False
    monkeypatch.delenv("PRINTEPS_PROCESS_WARM_UP")
    assert load_settings().engine.process_warm_up is True
    for settings, warms in ((off, False), (load_settings(), True)):
        settings.data_dir = str(tmp_path / f"d{warms}")
        settings.engine.rules_dir = str(tmp_path / "no-rules")
        settings.streams.queries_dir = None
        with built_gateway(settings, mongo, tmp_path / f"s{warms}", warm_up=True) as gateway:
            assert (gateway.engine._warm_up._thread is not None) is warms
