"""Issue 15's acceptance test: all sixteen Table-2 change requests made in a real Chromium the way
the teahouse owner would (workflow editor, rules editor, knowledge editor; no YAML, DRL or Python
typed for the workflow and knowledge changes), each followed by a check on the running gateway
that the robots' behaviour changed (a workflow run's trace, a rule fire, Pellet's inference).

The steps and the seconds per change are recorded (printed, not asserted: no timed assertions),
with a screenshot per change (docs/img/table2/NN.png with PRINTEPS_SCREENSHOTS=1). The changes
are in :mod:`table2_steps`, shared with ``bench/table2_browser.py``. The session's gateway is
shared with the other workbench tests, so everything changed is rolled back at the end.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest
from playwright.sync_api import Page

from gateway.config import PROJECT_ROOT
from agile_harness import TABLES, OwnerClient, behaviour
from table2_steps import Setup, make_all, markdown, prepare, restore, snapshot
from wb_helpers import AUTHOR_TOKEN, CALLER_TOKEN, REFUSED_REQUEST, console_errors, new_page

pytestmark = [pytest.mark.browser, pytest.mark.slow]  # a browser story: make test runs it, make test-fast not


@pytest.fixture()
def setup(gateway, tmp_path: Path) -> Iterator[Setup]:
    """The engineer's preparation (three rule files for seat_info); afterwards every
    workflow, rule set and knowledge version the changes made is rolled back."""
    setup = Setup(files=tmp_path / "from-the-engineer", seat_info=f"seat_info_{os.getpid()}")
    probes = OwnerClient(gateway.base_url, token=CALLER_TOKEN)
    with gateway.rest() as client:
        was = snapshot(client)
        behaved = teahouse_behaviour(probes)
        prepare(client, setup)
    yield setup
    with gateway.rest() as client:
        restore(client, was, setup)
    try:
        assert teahouse_behaviour(probes) == behaved, "the teahouse does not behave as before the test"
    finally:
        probes.close()


PROBED_RUNS = (("show_to_seat", None), ("prepare_drinks", {"orders": []}), ("take_order", None),
               ("settle_bill", None), ("greeting", {"tables": TABLES}),
               ("serving", {"cups": [{"table": "table1", "empty_for_s": 20}]}))
PROBED_INDIVIDUALS = [{"id": "kid6", "types": ["Customer"], "properties": {"age": 6}},
                      {"id": "cup200", "types": ["Cup"], "properties": {"cupCapacity": 200}}]


def teahouse_behaviour(gw: OwnerClient) -> dict[str, list[str]]:
    """What the robots do in every workflow the changes touch, and what Pellet infers for a child and
    a cup (the probes' inputs)."""
    seen = {name: behaviour(gw.run(name, inputs)) for name, inputs in PROBED_RUNS}
    seen["reason"] = sorted(str(fact) for fact in gw.reason(PROBED_INDIVIDUALS)["inferred"])
    return seen


@pytest.fixture()
def page(browser, gateway) -> Iterator[Page]:
    page = new_page(browser, gateway, AUTHOR_TOKEN)
    yield page
    page.context.close()
    # refused requests the views handle themselves (a 404 probe, a 422 check) are not script errors
    assert page.js_errors == [] and console_errors(page, REFUSED_REQUEST) == []


def test_all_sixteen_change_requests_by_the_owner_in_the_browser(page: Page, gateway, setup: Setup, tmp_path):
    shots = PROJECT_ROOT / "docs" / "img" / "table2" if os.environ.get("PRINTEPS_SCREENSHOTS") == "1" \
        else tmp_path / "table2"
    gw = OwnerClient(gateway.base_url, token=AUTHOR_TOKEN)
    try:
        done = make_all(page, gw, setup, shots)
    finally:
        gw.close()

    assert [d.id for d in done] == list(range(1, 17))
    for d in done:
        assert d.steps > 0 and (shots / d.screenshot).is_file()
        assert d.before != d.after, f"#{d.id}: the behaviour did not change"
    print("\n" + markdown(done, str(shots)))
