"""C-SPARQL parsing: what is accepted, and clear line/column errors for what is not."""

from __future__ import annotations

import pytest

from gateway.stream import QueryParseError, parse_query

from csparql_scenarios import CUSTOMER_QUERY

HEAD = "REGISTER QUERY q AS\nPREFIX ex: <http://ex/>\n"


def test_the_papers_query_parses():
    q = parse_query(CUSTOMER_QUERY)
    assert q.name == "CustomerDetectionQuery" and q.form == "SELECT"
    (w,) = q.windows
    assert (w.stream, w.range_ms, w.step_ms) == ("http://printeps.org/cafe/entrance", 3000, 1000)
    assert [p.name for p in q.params] == ["distance_to_entrance"]
    # the SPARQL keeps the layout: the same line/column for every remaining token
    assert len(q.sparql) == len(CUSTOMER_QUERY) and q.sparql.count("\n") == CUSTOMER_QUERY.count("\n")
    assert "FROM STREAM" not in q.sparql and "REGISTER" not in q.sparql
    assert "HAVING (AVG(?distance1) < 3.3 &&" in q.executable({"distance_to_entrance": "3.3"})


@pytest.mark.parametrize("window, expected", [
    ("[RANGE 500ms STEP 100ms]", (500, 100, None)),
    ("[RANGE 2m STEP 30s]", (120_000, 30_000, None)),
    ("[RANGE 1h TUMBLING]", (3_600_000, 3_600_000, None)),
    ("[RANGE 1.5s STEP 0.5s]", (1500, 500, None)),
    ("[RANGE TRIPLES 100]", (None, None, 100)),
])
def test_window_forms(window, expected):
    q = parse_query(HEAD + f"SELECT * FROM STREAM <http://s> {window} WHERE {{ ?a ?b ?c }}")
    w = q.windows[0]
    assert (w.range_ms, w.step_ms, w.triples) == expected


def test_several_streams_and_static_graphs():
    q = parse_query(HEAD + "SELECT * FROM STREAM <http://s1> [RANGE 3s STEP 1s]\n"
                    "FROM STREAM ex:s2 [RANGE 5s STEP 1s]\nFROM <http://g>\nFROM NAMED <http://n>\n"
                    "WHERE { ?a ?b ?c }")
    assert q.streams == ["http://s1", "http://ex/s2"]
    assert q.static_graphs == ["http://g"] and q.named_graphs == ["http://n"]


def test_param_directives():
    q = parse_query('PARAM ?x = 0.5\nPARAM ?y FROM ONTOLOGY "SELECT ?v WHERE { ?a ?b ?v }"\n' + HEAD
                    + "SELECT * FROM STREAM <http://s> [RANGE 1s STEP 1s] WHERE { ?a ?b ?c FILTER(?c > ?x) }")
    assert [(p.name, p.value) for p in q.params] == [("x", "0.5"), ("y", None)]
    assert "?c > 0.5" in q.executable({"x": "0.5", "y": "1"})


@pytest.mark.parametrize("text, line, column, words", [
    ("SELECT * WHERE { ?a ?b ?c }", 1, 1, "REGISTER QUERY"),
    (HEAD + "SELECT * WHERE { ?a ?b ?c }", 3, 27, "FROM STREAM"),
    (HEAD + "SELECT * FROM STREAM <http://s> [RANGE 1s STEP 3s] WHERE {}", 3, 43, "STEP (3000 ms) is larger"),
    (HEAD + "SELECT * FROM STREAM <http://s> [RANGE 0s STEP 0s] WHERE {}", 3, 34, "RANGE must be greater"),
    (HEAD + "SELECT * FROM STREAM <http://s> [RANGE 3s STEP 0s] WHERE {}", 3, 43, "STEP must be greater"),
    (HEAD + "SELECT * FROM STREAM <http://s> [RANGE 3 STEP 1s] WHERE {}", 3, 42, "time unit"),
    (HEAD + "SELECT * FROM STREAM <http://s> [RANGE 3s STEP 1s WHERE {}", 3, 51, "expected ]"),
    (HEAD + "SELECT * FROM STREAM <http://s> RANGE 3s WHERE {}", 3, 33, "[RANGE"),
    (HEAD + "SELECT * FROM STREAM <http://s> [RANGE TRIPLES 0] WHERE {}", 3, 48, "TRIPLES"),
    (HEAD + "SELECT * FROM STREAM <http://s> [RANGE 1s STEP 1s]\nWHERE { ?a foo:b ?c }", 4, 12, "unknown prefix 'foo'"),
    (HEAD + "SELECT * FROM STREAM <http://s> [RANGE 1s STEP 1s] WHERE { ?a ?b ?c ~ }", 3, 69, "unexpected character"),
    ("REGISTER QUERY AS SELECT", 1, 19, "expected AS"),
    ("", 1, 1, "empty"),
])
def test_errors_have_positions(text, line, column, words):
    with pytest.raises(QueryParseError) as info:
        parse_query(text)
    err = info.value
    assert words in err.message
    assert (err.line, err.column) == (line, column)
