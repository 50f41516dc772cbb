"""Issue 32, "documented behaviour is tested behaviour": the defects found by trying the docs as a
new user would (each test here failed before its fix), and one error body for the whole API —
every route that takes a JSON body, walked from the OpenAPI document, refuses a malformed body, a
wrong content type and an over-deep body at the door, with ``{"error", "kind", …}``."""

from __future__ import annotations

import re
import time
from datetime import datetime, timedelta, timezone

import pytest

from api_helpers import FACTS, files

KIE = "/kie-server/services/rest/server"
DEEP = b'{"facts": ' + b"[" * 200 + b"]" * 200 + b"}"
TRUNCATED = b'{"facts": [{"type": "Customer",\n  "id": '
#: Routes documented to take another content type as well (text/turtle): no 415 for them.
OTHER_CONTENT_TYPES = {"/api/reason"}


@pytest.fixture(scope="module")
def deployed(client) -> str:
    assert client.put("/api/rulesets/contract", json={"files": files()}).status_code == 201
    return "contract"


def test_an_id_already_open_is_409_and_a_declared_one_takes_the_facts(client, deployed):
    """Defect 1: a second create with an open id answered 200 with the session and dropped the facts."""
    base = f"/api/rulesets/{deployed}/sessions"
    assert client.post(base, json={"id": "dup"}).status_code == 201
    r = client.post(base, json={"id": "dup", "facts": FACTS})
    assert r.status_code == 409 and "already open" in r.json()["error"] and r.json()["kind"] == "session"
    assert client.get(f"{base}/dup").json()["fact_count"] == 0
    # a declared stateful ksession is opened or returned (200): the facts sent go into it
    first = client.post(base, json={"id": "defaultKieSession", "facts": FACTS[:1]})
    again = client.post(base, json={"id": "defaultKieSession", "facts": FACTS[1:]})
    assert first.status_code in (200, 201) and again.status_code == 200, again.json()
    assert len(again.json()["handles"]) == 1 and again.json()["fact_count"] == first.json()["fact_count"] + 1
    for sid in ("dup", "defaultKieSession"):
        assert client.delete(f"{base}/{sid}").status_code == 200


def test_a_fact_without_type_is_one_shape_on_fire_and_on_session_facts(client, deployed):
    """Defect 5: fire answered ``{"error": "bad facts"}`` without ``kind``, session facts pydantic's
    "invalid request"."""
    base = f"/api/rulesets/{deployed}/sessions"
    sid = client.post(base, json={}).json()["id"]
    bodies = {
        "fire": client.post(f"/api/rulesets/{deployed}/fire", json={"facts": [{"id": "x", "age": 3}]}),
        "create": client.post(base, json={"facts": [{"id": "x", "age": 3}]}),
        "insert": client.post(f"{base}/{sid}/facts", json={"facts": [{"id": "x", "age": 3}]}),
    }
    expected = {"index": 0, "type": None, "id": "x", "field": "type", "message": "a fact needs a non-empty string 'type'"}
    for route, r in bodies.items():
        assert r.status_code == 422, (route, r.json())
        assert r.json()["kind"] == "facts" and r.json()["errors"] == [expected], (route, r.json())
        assert r.json()["error"] == "fact 0: a fact needs a non-empty string 'type'", route
    assert client.get(f"{base}/{sid}").json()["fact_count"] == 0
    client.delete(f"{base}/{sid}")


def test_since_and_until_are_exact_to_the_millisecond(client, deployed):
    """Defect 3: the bounds kept whole seconds: ``since=…19.999Z`` returned a decision at ``…19.001Z``."""
    ids = []
    for _ in range(3):
        ids.append(client.post(f"/api/rulesets/{deployed}/fire", json={"facts": FACTS},
                               headers={"X-Request-ID": "exact-bounds"}).json()["decision_id"])
        time.sleep(0.003)  # distinct milliseconds, nothing waited on
    deadline = time.monotonic() + 30
    while True:  # decisions reach the database a few milliseconds after the answer
        found = client.get("/api/decisions", params={"ruleset": deployed, "limit": 1000}).json()["decisions"]
        ours = {d["decision_id"]: d["at"] for d in found if d["decision_id"] in ids}
        if len(ours) == 3 or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    assert len(ours) == 3
    ats = sorted(set(ours.values()))
    middle = ats[len(ats) // 2]
    moment = datetime.fromisoformat(middle.replace("Z", "+00:00"))

    def between(**bounds) -> set[str]:
        r = client.get("/api/decisions", params={"ruleset": deployed, "limit": 1000, **bounds})
        assert r.status_code == 200, r.json()
        return {d["at"] for d in r.json()["decisions"] if d["decision_id"] in ids}

    iso = lambda t: t.isoformat(timespec="microseconds").replace("+00:00", "Z")  # noqa: E731
    assert between(since=middle) == {a for a in ats if a >= middle}  # inclusive
    assert between(until=middle) == {a for a in ats if a < middle}  # exclusive
    assert between(since=iso(moment + timedelta(microseconds=500))) == {a for a in ats if a > middle}
    assert between(until=iso(moment + timedelta(microseconds=500))) == {a for a in ats if a <= middle}
    assert between(since=iso(moment + timedelta(milliseconds=1)), until=iso(moment + timedelta(seconds=1))) == \
        {a for a in ats if a > middle}


# -- the error table, on every route family ------------------------------------------------------

FAMILIES = {
    "fire": ("POST", "/api/rulesets/contract/fire"),
    "KIE": ("POST", f"{KIE}/containers/instances/contract"),
    "sessions": ("POST", "/api/rulesets/contract/sessions"),
    "management": ("PUT", "/api/rulesets/contract"),
    "validate": ("POST", "/api/rulesets/contract/validate"),
    "knowledge": ("POST", "/api/knowledge/ontology/check"),
    "streams": ("POST", "/api/streams"),
    "queries": ("POST", "/api/queries/validate"),
    "workflows": ("POST", "/api/workflows/validate"),
}


def _refusal(r, status: int, kind: str, kie: bool) -> dict:
    """The body of a refusal with ``status``: KIE's ``FAILURE`` under the KIE prefix, else ``{"error", "kind"}``."""
    assert r.status_code == status, (r.request.method, r.request.url.path, r.status_code, r.text[:300])
    body = r.json()
    if kie:
        assert body["type"] == "FAILURE" and body["msg"], body
    else:
        assert isinstance(body["error"], str) and body["error"] and body["kind"] == kind, body
    return body


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_the_error_table_holds_on_every_route_family(client, deployed, family):
    """Defect 4: XML on deploy/validate gave 422 "Input should be a valid dictionary", truncated JSON
    422 ``body.20``, a body nested 200 deep on sessions 422 from deep inside."""
    method, path = FAMILIES[family]
    kie = path.startswith(KIE)
    send = lambda body, ctype="application/json": client.request(  # noqa: E731
        method, path, content=body, headers={"Content-Type": ctype})
    _refusal(send(b"<facts/>", "application/xml"), 415, "media_type", kie)
    truncated = _refusal(send(TRUNCATED), 400, "body", kie)
    if kie:
        assert "line 2, column 9" in truncated["msg"], truncated
    else:
        assert (truncated["line"], truncated["column"]) == (2, 9), truncated
    deep = _refusal(send(DEEP), 400, "body", kie)
    assert "deeper than 64" in (deep["msg"] if kie else deep["error"])
    _refusal(send(b""), 400, "body", kie)
    big = _refusal(client.request(method, path, content=b" " * 10_485_761, headers={"Content-Type": "application/json"}),
                   413, "too_large", False)
    assert "limit is 10485760 bytes" in big["error"]


def _operations(client) -> list[tuple[str, str]]:
    """(method, path) of every operation of the OpenAPI document that takes a JSON body."""
    out = []
    for path, item in client.get("/openapi.json").json()["paths"].items():
        for method, op in item.items():
            if "application/json" in (op.get("requestBody") or {}).get("content", {}):
                out.append((method.upper(), path))
    return out


def test_every_json_body_route_of_the_openapi_document_refuses_bad_bodies_in_one_shape(client, deployed):
    """One error body for the whole API: each route taking a JSON body answers a malformed body 400
    (with line and column), a wrong content type 415 and an over-deep body 400, as
    ``{"error", "kind", ...}`` (KIE's routes: its ``FAILURE`` body) — before anything else is looked at."""
    operations = _operations(client)
    assert len(operations) >= 30 and ("PUT", "/api/rulesets/{name}") in operations
    for method, template in operations:
        path = re.sub(r"\{name\}|\{container_id\}", "contract", template)
        path = re.sub(r"\{[^}]+\}", "x1", path)
        kie = path.startswith(KIE)
        send = lambda body, ctype="application/json": client.request(  # noqa: E731
            method, path, content=body, headers={"Content-Type": ctype})
        malformed = _refusal(send(b'{"a": [1, 2'), 400, "body", kie)
        if not kie:
            assert (malformed["line"], malformed["column"]) == (1, 12), (method, path, malformed)
        if template not in OTHER_CONTENT_TYPES:
            _refusal(send(b"<a/>", "application/xml"), 415, "media_type", kie)
        _refusal(send(b'{"a": ' + b"[" * 100 + b"]" * 100 + b"}"), 400, "body", kie)


def test_the_kie_401_asks_for_what_its_header_asks_for(secured, deployed):
    """The KIE 401 body asked for a Bearer token while its WWW-Authenticate header asked for Basic."""
    r = secured.post(f"{KIE}/containers/instances/contract", json={"commands": []})
    assert r.status_code == 401 and r.headers["www-authenticate"].startswith("Basic")
    assert "Authorization: Basic" in r.json()["msg"], r.json()
    r = secured.post("/api/rulesets/contract/fire", json={"facts": []})
    assert r.status_code == 401 and r.headers["www-authenticate"] == "Bearer" and r.json()["kind"] == "auth"
    assert "Basic" not in r.json()["error"]


def test_a_validate_job_answers_as_the_synchronous_validate(client, deployed):
    """Validate answered ``ok``, its asynchronous job ``valid``: the job's result now has ``ok`` too."""
    body = {"files": {"bad.drl": "rule \"x\" when Customer( age > ) then end"}}
    now = client.post("/api/rulesets/contract/validate", json=body).json()
    job = client.post("/api/rulesets/contract/validate?async=true", json=body)
    assert job.status_code == 202
    deadline = time.monotonic() + 120
    while (done := client.get(job.headers["location"]).json())["status"] not in ("succeeded", "failed"):
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert done["result"]["ok"] is now["ok"] is False and done["result"]["valid"] is False
    assert done["result"]["errors"] == now["errors"]


# -- the other rows of the error table, family by family -----------------------------------------

AUTHOR, CALLER = {"Authorization": "Bearer tok-author"}, {"Authorization": "Bearer tok-caller"}
#: family -> (method, path, JSON body) of a route only authors may call
AUTHOR_ROUTES = {
    "management": ("PUT", "/api/rulesets/contract", {"files": files()}),
    "KIE": ("DELETE", f"{KIE}/containers/contract", None),
    "knowledge": ("PUT", "/api/knowledge/swrl", {"text": ""}),
    "streams": ("POST", "/api/queries", {"query": "REGISTER QUERY X AS SELECT ?s WHERE { ?s ?p ?o }"}),
    "workflows": ("PUT", "/api/workflows/greeting", {"text": "workflow: greeting\n"}),
}
#: family -> (method, path) of a route naming something that does not exist, and the kind of its 404
NOT_FOUND = {
    "fire": ("POST", "/api/rulesets/no_such_set/fire", {"facts": []}, "not_found"),
    "KIE": ("GET", f"{KIE}/containers/no_such_set", None, None),
    "sessions": ("GET", "/api/rulesets/contract/sessions/no-such-session", None, "session"),
    "management": ("GET", "/api/rulesets/no_such_set", None, "not_found"),
    "knowledge": ("GET", "/api/knowledge/individuals/no_such_one", None, "not_found"),
    "streams": ("GET", "/api/queries/NoSuchQuery", None, "not_found"),
    "workflows": ("GET", "/api/workflows/no_such_flow", None, "not_found"),
}


@pytest.mark.parametrize("family", sorted(AUTHOR_ROUTES))
def test_401_without_credentials_and_403_for_a_caller_on_every_family(secured, deployed, family):
    method, path, body = AUTHOR_ROUTES[family]
    kie = path.startswith(KIE)
    _refusal(secured.request(method, path, json=body), 401, "auth", kie)
    _refusal(secured.request(method, path, json=body, headers=CALLER), 403, "forbidden", kie)


@pytest.mark.parametrize("family", sorted(NOT_FOUND))
def test_404_names_what_is_missing_on_every_family(client, deployed, family):
    method, path, body, kind = NOT_FOUND[family]
    r = client.request(method, path, json=body)
    if kind is None:  # KIE Server answers an unknown container with a 200 FAILURE, as KIE does
        assert r.json()["type"] == "FAILURE" and "is not instantiated" in r.json()["msg"]
    else:
        _refusal(r, 404, kind, False)


def test_409_a_stale_base_version_names_the_current_one_on_every_family(client, deployed):
    current = client.get("/api/rulesets/contract").json()["version"]
    r = client.put("/api/rulesets/contract", json={"files": files(), "base_version": current + 5})
    assert _refusal(r, 409, "conflict", False)["current"] == current
    flow = client.get("/api/workflows/greeting").json()
    r = client.put("/api/workflows/greeting", json={"text": flow["text"], "base_version": 999})
    assert _refusal(r, 409, "conflict", False)["current"] >= 1
    r = client.put("/api/knowledge/swrl", json={"text": client.get("/api/knowledge/swrl").json()["text"],
                                                 "base_hash": "0" * 16})
    assert _refusal(r, 409, "conflict", False)["current"]


def test_422_request_shape_is_one_body_on_every_family(client, deployed):
    for method, path, body in (("PUT", "/api/rulesets/contract", {"files": {"a.drl": 3}}),
                               ("POST", "/api/rulesets/contract/sessions", {"clock": "sundial"}),
                               ("POST", "/api/knowledge/ontology/check", {"txt": ""}),
                               ("POST", "/api/workflows/validate", {"text": 3}),
                               ("POST", "/api/mappings/validate", {"spec": {}, "extra": 1})):
        r = _refusal(client.request(method, path, json=body), 422, "request", False)
        assert r["error"] == "invalid request" and r["errors"][0]["field"].startswith("body."), (path, r)


def test_json_sent_as_text_plain_or_without_a_content_type_is_read_on_every_route_as_on_fire(client, deployed):
    """The door reads what the fire route reads: JSON declared as JSON, as ``text/plain`` or not at all."""
    for headers in ({"Content-Type": "text/plain"}, {}, {"Content-Type": "application/merge-patch+json"}):
        r = client.post("/api/rulesets/contract/sessions", content=b'{"facts": [{"type": "Customer", "id": "t", "age": 40}]}',
                        headers=headers)
        assert r.status_code == 201 and r.json()["fact_count"] == 1, (headers, r.json())
        assert client.delete(f"/api/rulesets/contract/sessions/{r.json()['id']}").status_code == 200
        r = client.post("/api/rulesets/contract/fire", content=b'{"facts": []}', headers=headers)
        assert r.status_code == 200, (headers, r.json())
