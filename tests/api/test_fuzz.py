"""Fuzzing every operation of /openapi.json with schemathesis: no answer may be a 5xx.

Runs on its own gateway (own database) so random deletes/deploys cannot touch other tests' rule
sets; the JVM and the database server are the session's.
"""

from __future__ import annotations

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
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
        yield schemathesis.openapi.from_asgi("/openapi.json", gateway.app)


FUZZ = settings(max_examples=25, deadline=None, derandomize=True, database=None,
                suppress_health_check=list(HealthCheck))


@pytest.mark.timeout(900)  # ~30 operations x 25 requests, some compiling rules: minutes on a busy 2-core machine
def test_no_server_errors(fuzz_schema):
    """Every operation, a dozen generated requests each (deterministic), only the 5xx check."""
    operations = [result.ok() for result in fuzz_schema.get_all_operations()]
    assert len(operations) >= 20
    for operation in operations:

        @FUZZ
        @given(case=operation.as_strategy())
        def run(case):
            case.call_and_validate(headers=AUTH, checks=[not_a_server_error])

        run()
