"""The rule policy in the workbench (issue 26): an author sees their role and, in the editor, why a
rule is refused — at its line, like any other problem — and cannot try or deploy it."""

from __future__ import annotations

import pytest
from playwright.sync_api import expect

from wb_helpers import EDITOR, open_ruleset, replace_text

pytestmark = pytest.mark.browser


def test_an_author_sees_why_a_rule_is_refused(author_page, gateway, ruleset):
    page = author_page
    open_ruleset(page, ruleset)
    expect(page.get_by_test_id("role")).to_contain_text("(author)")
    assert "rule policy" in (page.get_by_test_id("role").get_attribute("title") or "")
    replace_text(page, 'Pepper says "Welcome. Two seats?"', '> System.exit(1);')
    problem = page.get_by_test_id("problems").locator("li")
    expect(problem.first).to_contain_text("rule policy: class 'java.lang.System'")
    expect(page.locator(f"{EDITOR} .cm-lintRange-error").first).to_contain_text("System")
    page.get_by_test_id("deploy").click()
    expect(page.get_by_test_id("deploy-result")).to_contain_text("the rule policy refuses 1 place(s) for your role")
    with gateway.rest() as client:
        assert client.get(f"/api/rulesets/{ruleset}").json()["version"] == 1
        history = client.get(f"/api/rulesets/{ruleset}/history").json()
    assert history[-1]["event"] == "refused" and history[-1]["role"] == "author"
