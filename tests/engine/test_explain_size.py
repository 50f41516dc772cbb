"""Explain on large rule sets: its diagnostic queries are packed into as few packages as the
bounds of a rule set's files allow, and a set too large to explain is refused with a clear error
instead of "rule set too large" of a set that is deployed. A real JVM and Drools."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from gateway.engine.explain import ExplainTooLarge, _check_size
from gateway.engine.explain_plan import QUERIES_PER_PACKAGE, plan_rules, query_files
from gateway.engine.ruleset import MAX_FILES

from engine_samples import engine_with

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench" / "peers"))
import growth_rules  # noqa: E402


def test_a_1500_rule_set_is_explained_whole(tmp_path):
    files = growth_rules.drl_files(1500)
    plans, sources = plan_rules(files)
    queries = query_files(plans, sources)
    assert len(queries) + len(sources) <= MAX_FILES  # 40 a package would make ~220 files
    written = sum(text.count('query "') for text in queries.values())
    assert written > QUERIES_PER_PACKAGE * MAX_FILES
    engine = engine_with(tmp_path, "big", files, explain_prebuild=False)
    facts = growth_rules.sample_facts(3)
    answer = engine.explain("big", facts)
    assert len(answer["rules"]) == 1500
    assert sorted(answer["fired"]) == sorted(f["rule"] for f in engine.fire("big", facts).fired)
    assert all(rule["fired"] or rule.get("reason") for rule in answer["rules"])


def test_a_set_too_large_to_explain_is_refused_with_its_figures():
    plans, _sources = plan_rules({"r.drl": 'rule "r" when String() then end\n'})
    files = {f"zz_explain_{n}.drl": 'query "q"\n    String( )\nend\n' * 20_000 for n in range(1, 11)}
    with pytest.raises(ExplainTooLarge, match=r"its 1 rules need 200,000 diagnostic queries \(5\.6 MB of DRL; "
                                              r"explain builds at most 5 MB in 200 files"):
        _check_size(plans, files)
    _check_size(plans, dict(list(files.items())[:5]))  # 2.8 MB: explained
