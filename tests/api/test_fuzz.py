"""Fuzzing every operation of /openapi.json with schemathesis: no answer may be a 5xx.

Runs on its own gateway (own database) so random deletes/deploys cannot touch other tests' rule
sets; the JVM and the database server are the session's.

The streaming (server-sent events) operations are not fuzzed here: a live feed is endless by
design, and the in-process client reads a response to its end, so each generated request idled
until the feed's keep-alive (this test once spent ~8 minutes of the suite so). Their parameters
are checked where they are served for real (tests/api/test_live.py, tests/stream/test_api.py).
"""

from __future__ import annotations

import pytest
import schemathesis
from fastapi.routing import APIRoute
from hypothesis import HealthCheck, given, seed, settings
from schemathesis.checks import not_a_server_error

from api_helpers import files, make_settings
from gw_testing import built_gateway

TOKEN = "fuzz-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}  # a valid author token, so requests get past auth


@pytest.fixture(scope="module")
def fuzz_schema(tmp_path_factory, mongo):
    fuzz_settings = make_settings(tmp_path_factory.mktemp("fuzz"), tokens=f"{TOKEN}:author:fuzzer")
    with built_gateway(fuzz_settings, mongo, tmp_path_factory.mktemp("fuzz-store")) as gateway:
        gateway.engine.deploy("fuzz", files("f1"))  # something real to hit besides random names
        schema = schemathesis.openapi.from_asgi("/openapi.json", gateway.app)
        schema.streaming_paths = streaming_paths()
        yield schema


def streaming_paths() -> set[str]:
    """The paths whose endpoint answers a stream (declared to return a StreamingResponse), from the
    routers the app is made of (the app itself lists included routers, not their routes)."""
    from gateway.api.main import ROUTERS

    paths = set()
    for router in ROUTERS:
        for route in router.routes:
            if isinstance(route, APIRoute) and "StreamingResponse" in str(route.endpoint.__annotations__.get("return")):
                paths.add(route.path)
    return paths


def _fuzz(schema, examples: int, seed_value: int) -> None:
    """Every operation but the live feeds, ``examples`` generated requests each (deterministic by
    ``seed_value``), only the 5xx check."""
    operations = [result.ok() for result in schema.get_all_operations()]
    operations = [op for op in operations if op.path not in schema.streaming_paths]
    assert len(operations) >= 20
    for operation in operations:

        @seed(seed_value)
        @settings(max_examples=examples, deadline=None, database=None, suppress_health_check=list(HealthCheck))
        @given(case=operation.as_strategy())
        def run(case):
            case.call_and_validate(headers=AUTH, checks=[not_a_server_error])

        run()


def test_the_streaming_operations_left_out_are_exactly_the_live_feeds(fuzz_schema):
    assert fuzz_schema.streaming_paths == {"/api/live", "/api/streams/live", "/api/queries/{name}/live"}


# 25 generated requests an operation in all (~120 operations): 8 in the inner loop (make test-fast),
# 17 more, other ones (another seed), in the full run. Split so the inner loop still fuzzes every
# operation while the full suite does what it always did; 25 in one test took 43 s on a quiet machine.
@pytest.mark.timeout(600)  # a safety limit: ~120 operations x 8 requests, some compiling rules
def test_no_server_errors(fuzz_schema):
    _fuzz(fuzz_schema, examples=8, seed_value=0)


@pytest.mark.slow
@pytest.mark.timeout(900)  # a safety limit: ~120 operations x 17 requests
def test_no_server_errors_in_depth(fuzz_schema):
    _fuzz(fuzz_schema, examples=17, seed_value=1)
