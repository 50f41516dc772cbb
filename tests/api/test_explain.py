"""Explain and trace over REST (real JVM, real MongoDB-protocol server): for every rule, fired with
its matches or the condition that stopped it, in the author's words (DRL, DSL sentence, decision
table cell); not/exists/accumulate said in those terms; nothing recorded. A trace of a REST fire."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "engine"))
from authoring_samples import csv_text, files_with, group  # noqa: E402

DRL = """package org.printeps.explaintest;

import org.printeps.gateway.Actions;

global Actions actions;

declare Guest
    id : String
    age : int
    language : String
end

declare Crowded
    hall : String
end

declare Visit
    guest : String
end

rule "Greet in English"
when
    $g : Guest( age >= 12, language == "en" )
    not Crowded( hall == "main" )
then
    actions.say("pepper", "Hello " + $g.getId());
end

rule "Regular"
when
    $g : Guest( )
    Number( intValue >= 5 ) from accumulate( Visit( guest == $g.id ), count(1) )
then
    actions.say("pepper", "Welcome back " + $g.getId());
end

rule "Loyal guest"
when
    $g : Guest( )
    accumulate( Visit( guest == $g.id ); $n : count( 1 ); $n >= 5 )
then
    actions.say("pepper", "Thank you for coming again");
end

rule "Spring greeting"
date-effective "1-Mar-2099"
when
    Guest( )
then
    actions.say("pepper", "Happy spring");
end

rule "Side hall crowded"
when
    exists Crowded( hall == "side" )
then
    actions.say("pepper", "The side hall is full");
end

rule "Any guest"
when
    Guest( )
then
    actions.say("pepper", "Hello");
end
"""

DSL = """[condition][]There is a guest=$g: Guest()
[condition][]- older than {n:\\d+}=age > {n}
[condition][]- who speaks "{lang}"=language == "{lang}"
[condition][]The main hall is not crowded=not Crowded(hall == "main")
[consequence][]Greet the guest=actions.say("pepper", "Hello " + $g.getId());
"""

DSLR = """package org.printeps.explaintest;

expander guests.dsl

rule "Greet English speakers"
when
    There is a guest
    - older than 11
    - who speaks "en"
    The main hall is not crowded
then
    Greet the guest
end
"""

TYPES = DRL[:DRL.index('rule "Greet in English"')]


def by_rule(answer: dict) -> dict[str, dict]:
    return {r["rule"]: r for r in answer["rules"]}


@pytest.fixture(scope="module")
def drl_set(client):
    assert client.put("/api/rulesets/explain-drl", json={"files": {"r.drl": DRL}}).status_code == 201
    return "explain-drl"


def test_drl_rules_say_what_stopped_them(client, api_gateway, drl_set):
    facts = [{"type": "Guest", "id": "g1", "age": 30, "language": "fr"}, {"type": "Crowded", "hall": "main"},
             *[{"type": "Visit", "guest": "g1"}] * 3]
    api_gateway.store.flush(30)
    decisions_before = api_gateway.store.db["decisions"].count_documents({"ruleset": drl_set})
    answer = client.post(f"/api/rulesets/{drl_set}/explain", json={"facts": facts})
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert body["version"] == 1 and body["fired"] == ["Any guest"]
    rules = by_rule(body)
    assert rules["Any guest"]["fired"] is True
    assert rules["Any guest"]["matches"] == [[{"type": "Guest", "id": "g1", "age": 30, "language": "fr"}]]
    english = rules["Greet in English"]
    assert english["fired"] is False
    assert english["condition"]["index"] == 1 and english["condition"]["of"] == 2
    assert english["condition"]["drl"] == '$g : Guest( age >= 12, language == "en" )'
    assert english["condition"]["file"] == "r.drl" and english["condition"]["line"] == 23
    assert english["constraint"] == 'language == "en"'
    assert english["closest"]["value"] == "fr" and english["closest"]["passed"] == 1
    assert english["reason"].startswith('language is "fr", the rule wants "en"')
    regular = rules["Regular"]
    assert regular["condition"]["kind"] == "accumulate" and regular["condition"]["index"] == 2
    assert regular["reason"] == "the accumulated value is 3, the rule wants intValue >= 5"
    loyal = rules["Loyal guest"]  # the accumulate element: its result by the name it is bound to
    assert loyal["condition"]["kind"] == "accumulate" and loyal["condition"]["index"] == 2
    assert loyal["constraint"] == "$n >= 5" and loyal["closest"]["value"] == 3
    assert loyal["reason"] == "$n is 3, the rule wants $n >= 5"
    spring = rules["Spring greeting"]  # its conditions hold: what held it back is its attribute
    assert spring["fired"] is False and spring["condition"] is None
    assert spring["reason"] == "all its conditions hold, but it did not fire: it takes effect on 1-Mar-2099 (date-effective)"
    side = rules["Side hall crowded"]
    assert side["condition"]["kind"] == "exists"
    assert side["reason"].startswith("no Crowded fact exists that matches") and '"main"' in side["reason"]
    api_gateway.store.flush(30)
    assert api_gateway.store.db["decisions"].count_documents({"ruleset": drl_set}) == decisions_before


def test_attributes_written_for_a_whole_file_are_said_for_its_rules(client, drl_set):
    files = {"r.drl": TYPES.replace("global Actions actions;", 'global Actions actions;\ndate-expires "1-Jan-2001"') + """
rule "Old greeting"
when
    Guest( )
then
    actions.say("pepper", "Hi");
end
"""}
    answer = client.post(f"/api/rulesets/{drl_set}/explain", json={"files": files, "facts": [{"type": "Guest", "id": "g"}]})
    assert answer.status_code == 200, answer.text
    assert by_rule(answer.json())["Old greeting"]["reason"].endswith("it expired on 1-Jan-2001 (date-expires)")


def test_a_not_condition_shows_the_fact_that_exists(client, drl_set):
    facts = [{"type": "Guest", "id": "g2", "age": 40, "language": "en"}, {"type": "Crowded", "hall": "main"}]
    english = by_rule(client.post(f"/api/rulesets/{drl_set}/explain", json={"facts": facts}).json())["Greet in English"]
    assert english["condition"]["kind"] == "not" and english["condition"]["index"] == 2
    assert english["exists"] == [{"type": "Crowded", "hall": "main"}]
    assert "Crowded" in english["reason"] and "exists" in english["reason"]
    fired = client.post(f"/api/rulesets/{drl_set}/explain", json={"facts": facts[:1]}).json()
    assert by_rule(fired)["Greet in English"]["fired"] is True


def test_dsl_conditions_are_told_in_the_authors_sentences(client):
    files = {"types.drl": TYPES, "guests.dsl": DSL, "greet.dslr": DSLR}
    answer = client.post("/api/rulesets/explain-dsl/explain",
                         json={"files": files, "facts": [{"type": "Guest", "id": "g1", "age": 30, "language": "fr"}]})
    assert answer.status_code == 200, answer.text
    rule = by_rule(answer.json())["Greet English speakers"]
    assert "hash" in answer.json()
    assert rule["condition"]["file"] == "greet.dslr" and rule["condition"]["line"] == 7
    assert rule["condition"]["written"] == 'There is a guest\n- older than 11\n- who speaks "en"'
    assert rule["reason"].startswith('language is "fr", the rule wants "en"')
    crowded = client.post("/api/rulesets/explain-dsl/explain",
                          json={"files": files, "facts": [{"type": "Guest", "id": "g1", "age": 30, "language": "en"},
                                                          {"type": "Crowded", "hall": "main"}]}).json()
    rule = by_rule(crowded)["Greet English speakers"]
    assert rule["condition"]["written"] == "The main hall is not crowded" and rule["condition"]["line"] == 10
    assert rule["condition"]["kind"] == "not"


def test_decision_table_rules_point_at_their_row(client):
    files = files_with("greetings.csv", csv_text())
    answer = client.post("/api/rulesets/explain-table/explain", json={"files": files, "facts": [group("pair", 1)]})
    assert answer.status_code == 200, answer.text
    rules = by_rule(answer.json())
    assert rules["Greet anyone"]["fired"] is True
    pair = rules["Greet a pair"]
    assert pair["fired"] is False and pair["constraint"] == "size >= 2"
    assert pair["reason"].startswith("size is 1, the rule wants size >= 2")
    assert pair["condition"]["file"] == "greetings.csv" and pair["condition"]["cell"]
    family = rules["Greet a family"]
    assert family["reason"].startswith('kind is "pair", the rule wants "family"')


OR_FORALL = """package org.printeps.explaintest2;

declare Guest
    id : String
    age : int
    language : String
end

declare Ticket
    owner : String
end

rule "Senior or English child"
when
    Guest( age >= 65 ) or Guest( age < 12, language == "en" )
then
end

rule "Every guest has a ticket"
when
    forall( $g : Guest( ) Ticket( owner == $g.id ) )
then
end

rule "Every guest is an English-speaking adult"
when
    forall( Guest( age >= 18, language == "en" ) )
then
end
"""


def test_or_and_forall_say_which_alternative_came_closest_and_which_element_breaks(client):
    facts = [{"type": "Guest", "id": "g1", "age": 30, "language": "en"},
             {"type": "Guest", "id": "g2", "age": 10, "language": "fr"},
             {"type": "Ticket", "owner": "g1"}]
    answer = client.post("/api/rulesets/explain-drl/explain", json={"files": {"o.drl": OR_FORALL}, "facts": facts})
    assert answer.status_code == 200, answer.text
    rules = by_rule(answer.json())
    either = rules["Senior or English child"]
    assert either["fired"] is False and either["condition"]["kind"] == "or"
    assert either["closest_alternative"] == 2 and either["constraint"] == 'language == "en"'
    assert [a["index"] for a in either["alternatives"]] == [1, 2]
    assert either["alternatives"][0]["reason"].startswith("there is no Guest") is False  # g1/g2 exist: age fails
    assert either["reason"].startswith("none of its 2 alternatives holds; the closest is alternative 2")
    assert 'language is "fr", the rule wants "en"' in either["reason"] and 'Guest "g2"' in either["reason"]
    tickets = rules["Every guest has a ticket"]
    assert tickets["condition"]["kind"] == "forall" and [f["id"] for f in tickets["violating"]] == ["g2"]
    assert tickets["reason"].startswith('Guest "g2" matches $g : Guest( ) but has no Ticket( owner == $g.id )')
    adults = rules["Every guest is an English-speaking adult"]
    assert adults["constraint"] == "age >= 18" and [f["id"] for f in adults["violating"]] == ["g2"]
    assert adults["reason"] == 'Guest "g2" breaks the forall: age is 10, the rule wants age >= 18 for every Guest'
    # once g2 has a ticket and speaks English as an adult, the foralls hold and those rules fire
    grown = [facts[0], {"type": "Guest", "id": "g2", "age": 40, "language": "en"}, facts[2],
             {"type": "Ticket", "owner": "g2"}]
    rules = by_rule(client.post("/api/rulesets/explain-drl/explain",
                                json={"files": {"o.drl": OR_FORALL}, "facts": grown}).json())
    assert rules["Every guest has a ticket"]["fired"] and rules["Every guest is an English-speaking adult"]["fired"]


def test_decision_table_conditions_are_shown_in_the_cells_words(client):
    files = files_with("greetings.csv", csv_text())
    answer = client.post("/api/rulesets/explain-table/explain", json={"files": files, "facts": [group("pair", 1)]})
    family = by_rule(answer.json())["Greet a family"]
    assert family["condition"]["written"].split("\n") == ["$g: Group", "Kind: family", "At least: 3"]
    assert family["condition"]["cell"] == "C8"


def test_a_recorded_decision_is_explained_on_its_version(client, drl_set):
    facts = [{"type": "Guest", "id": "g3", "age": 8, "language": "en"}]
    fired = client.post(f"/api/rulesets/{drl_set}/fire", json={"facts": facts}).json()
    answer = client.get(f"/api/decisions/{fired['decision_id']}/explain")
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert body["decision_id"] == fired["decision_id"] and body["version"] == 1
    assert body["recorded"]["fired"] == [f["rule"] for f in fired["fired"]] == body["fired"]
    assert by_rule(body)["Greet in English"]["reason"].startswith("age is 8, the rule wants age >= 12")
    assert client.get("/api/decisions/0123456789abcdef01234567/explain").status_code == 404


def test_bad_explain_requests_are_told(client, drl_set):
    broken = client.post(f"/api/rulesets/{drl_set}/explain",
                         json={"files": {"r.drl": DRL.replace("age >= 12,", "age >=,")}, "facts": []})
    assert broken.status_code == 422 and broken.json()["errors"][0]["file"] == "r.drl"
    bad_facts = client.post(f"/api/rulesets/{drl_set}/explain", json={"facts": [{"id": "no type"}]})
    assert bad_facts.status_code == 422
    assert client.post("/api/rulesets/nope/explain", json={"facts": []}).status_code == 404
    assert client.post(f"/api/rulesets/{drl_set}/explain", json={"facts": [], "version": 9}).status_code == 404


def test_a_rest_fire_is_traced_by_its_request_id(client, api_gateway, drl_set):
    facts = [{"type": "Guest", "id": "g4", "age": 20, "language": "en"}]
    fired = client.post(f"/api/rulesets/{drl_set}/fire", json={"facts": facts},
                        headers={"X-Request-ID": "trace-me-29"}).json()
    api_gateway.store.flush(30)
    answer = client.get("/api/traces/trace-me-29")
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert [i["kind"] for i in body["items"]] == ["decision"]
    assert body["items"][0]["record"]["decision_id"] == fired["decision_id"]
    assert body["items"][0]["record"]["actions"] == fired["actions"]
    assert body["items"][0]["at"][:10] == body["items"][0]["record"]["at"][:10]  # when it was written: that day
    missing = client.get("/api/traces/never-seen")
    assert missing.status_code == 404 and "never-seen" in missing.json()["error"]


def test_an_explanation_after_a_deploy_compiles_nothing(client, api_gateway):
    """With ``engine.explain_prebuild`` the deploy builds the version's explain queries on the
    explain thread; the explanation afterwards finds them: no explainer built, no compile."""
    from gateway.engine import compiler
    from gw_testing import wait_for

    engine = api_gateway.engine
    files = {"r.drl": DRL.replace('"Hello"', '"Hello again"')}  # a text no other test built
    engine.settings.engine.explain_prebuild = True
    try:
        assert client.put("/api/rulesets/explain-prebuilt", json={"files": files}).status_code == 201
        assert wait_for(lambda: engine.explain_ready(files), timeout_s=120), "the explain queries were not built"
    finally:
        engine.settings.engine.explain_prebuild = False
    builds, compiles = engine.explain_builds(), compiler.stats["compiles"]
    answer = client.post("/api/rulesets/explain-prebuilt/explain",
                         json={"facts": [{"type": "Guest", "id": "g9", "age": 30, "language": "fr"}]})
    assert answer.status_code == 200, answer.text
    assert by_rule(answer.json())["Greet in English"]["fired"] is False
    assert engine.explain_builds() == builds and compiler.stats["compiles"] == compiles


def test_a_rule_set_over_the_prebuild_limit_builds_at_its_first_explanation(client, api_gateway):
    """``engine.explain_prebuild_max_rules``: a version with more rules than the limit queues no
    build in advance (its queries' compile would hold the compiler its next deploy needs); its
    first explanation builds them."""
    from gateway.engine import compiler

    engine = api_gateway.engine
    files = {"r.drl": DRL.replace('"Hello"', '"Hello, big set"')}  # a text no other test built
    engine.settings.engine.explain_prebuild = True
    engine.settings.engine.explain_prebuild_max_rules = 1
    try:
        assert client.put("/api/rulesets/explain-over-limit", json={"files": files}).status_code == 201
        assert engine.rule_count("explain-over-limit") > 1
        assert not engine.explain_ready(files)
        builds, compiles = engine.explain_builds(), compiler.stats["compiles"]
        answer = client.post("/api/rulesets/explain-over-limit/explain", json={"facts": []})
    finally:
        engine.settings.engine.explain_prebuild = False
        engine.settings.engine.explain_prebuild_max_rules = 200
    assert answer.status_code == 200, answer.text
    assert engine.explain_builds() == builds + 1 and compiler.stats["compiles"] > compiles


def test_without_prebuild_the_first_explanation_builds(client, api_gateway):
    """The counter the test above relies on does count: an explanation of a text nobody built
    builds its explainer (and compiles)."""
    from gateway.engine import compiler

    engine = api_gateway.engine
    files = {"r.drl": DRL.replace('"Hello"', '"Hello there"')}
    builds, compiles = engine.explain_builds(), compiler.stats["compiles"]
    answer = client.post("/api/rulesets/explain-drl/explain", json={"facts": [], "files": files})
    assert answer.status_code == 200, answer.text
    assert engine.explain_builds() == builds + 1 and compiler.stats["compiles"] > compiles
