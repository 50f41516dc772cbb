"""Issue 31's measure: all sixteen Table-2 changes made in a real Chromium by a newcomer who only
reads the screen — every control found by its words, no keyboard shortcuts, no test ids or typed
URLs, nothing typed but the sentence, name or value being changed — each checked on the running
gateway (the robots' behaviour changed), and each estimated for a person (clicks, typing, the words
the step reads at 200 words a minute, 2 s per new screen; :mod:`newcomer_steps`) and held under a
minute, every one of them.

With PRINTEPS_SCREENSHOTS=1 the screenshots go to docs/img/newcomer/ and the table printed is the
one in docs/agile-loop.md. The session's gateway is shared, so every change is rolled back after.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest
from playwright.sync_api import Page

from gateway.config import PROJECT_ROOT
from agile_harness import OwnerClient
from newcomer_steps import ONE_MINUTE, make_all, markdown, steps_markdown
from table2_steps import Setup, prepare, restore, snapshot
from test_table2_browser import teahouse_behaviour
from wb_helpers import AUTHOR_TOKEN, CALLER_TOKEN, REFUSED_REQUEST, console_errors, new_page

pytestmark = [pytest.mark.browser, pytest.mark.slow]


@pytest.fixture()
def setup(gateway, tmp_path: Path) -> Iterator[Setup]:
    """The engineer's three rule files for seat_info; afterwards everything the changes made is
    rolled back and the teahouse behaves as before."""
    # a short name (typed by the newcomer) that sorts before the other tests' rule sets in menus
    setup = Setup(files=tmp_path / "from-the-engineer", seat_info=f"cafe_seats{os.getpid() % 1000}")
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


@pytest.fixture()
def page(browser, gateway) -> Iterator[Page]:
    page = new_page(browser, gateway, AUTHOR_TOKEN)
    yield page
    page.context.close()
    assert page.js_errors == [] and console_errors(page, REFUSED_REQUEST) == []


def test_a_newcomer_makes_each_table2_change_in_under_a_minute(page: Page, gateway, setup: Setup, tmp_path):
    shots = PROJECT_ROOT / "docs" / "img" / "newcomer" if os.environ.get("PRINTEPS_SCREENSHOTS") == "1" \
        else tmp_path / "newcomer"
    gw = OwnerClient(gateway.base_url, token=AUTHOR_TOKEN)
    try:
        made = make_all(page, gw, setup, shots)
    finally:
        gw.close()
    print("\n" + markdown(made) + "\n\n" + steps_markdown(made))

    assert [m.id for m in made] == [*map(str, range(1, 8)), "8a", "8b", *map(str, range(9, 17))]
    for m in made:
        assert m.before != m.after, f"#{m.id}: the behaviour did not change"
        assert m.actions > 0 and m.words > 0 and (shots / m.screenshot).is_file()
        assert not any("press" in step for step in m.log), f"#{m.id} used a key: {m.log}"
        assert m.person_s < ONE_MINUTE, f"#{m.id} takes a person {m.person_s:.0f} s: {m.log}"
