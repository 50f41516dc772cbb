"""C-SPARQL parsing: what is accepted, and clear line/column errors for what is not."""

from __future__ import annotations

import pytest
from csparql_scenarios import CUSTOMER_QUERY

from gateway.stream import QueryParseError, ReportPolicy, parse_query

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


# -- RSP-QL additions ---------------------------------------------------------------------------


def test_report_clause_and_stream_operator():
    q = parse_query("REGISTER QUERY q REPORT ON CONTENT CHANGE AND NON EMPTY AS\nPREFIX ex: <http://ex/>\n"
                    "SELECT ISTREAM ?a FROM STREAM <http://s> [RANGE 1s STEP 1s] WHERE { ?a ?b ?c }")
    assert q.report == ReportPolicy("content_change", True, None)
    assert q.r2s == "ISTREAM" and "ISTREAM" not in q.sparql and len(q.sparql) == len(q.text)
    assert parse_query(HEAD + "SELECT * FROM STREAM <http://s> [RANGE 1s STEP 1s] WHERE {}").report == ReportPolicy()
    assert ReportPolicy.parse("periodic PT2S") == ReportPolicy("periodic", False, 2000)


def test_named_windows_and_window_patterns():
    q = parse_query("REGISTER QUERY q AS PREFIX w: <http://ex/w/>\nSELECT * FROM NAMED WINDOW w:a ON <http://s> "
                    "[RANGE 5s STEP 1s]\nFROM NAMED STREAM <http://t> [RANGE TRIPLES 4]\n"
                    "WHERE { WINDOW w:a { ?x ?y ?z } GRAPH <http://t> { ?x ?y ?z } }")
    assert [(w.name, w.stream) for w in q.windows] == [("http://ex/w/a", "http://s"), ("http://t", "http://t")]
    assert "GRAPH  w:a {" in q.sparql and "WINDOW" not in q.sparql  # same length: positions are kept


def test_register_stream_names_its_output():
    q = parse_query("REGISTER STREAM ex:out AS PREFIX ex: <http://ex/>\nCONSTRUCT { ?a ?b ?c } "
                    "FROM STREAM <http://s> [RANGE 1s STEP 1s] WHERE { ?a ?b ?c }")
    assert (q.kind, q.name, q.output_stream) == ("STREAM", "ex:out", "http://ex/out")
    assert parse_query("REGISTER STREAM s AS CONSTRUCT { ?a ?b ?c } FROM STREAM <t> [RANGE 1s STEP 1s] "
                       "WHERE { ?a ?b ?c }").output_stream == "s"


def test_parameter_range():
    q = parse_query('PARAM ?r = 3\n' + HEAD + "SELECT * FROM STREAM <http://s> [RANGE ?r STEP 1s] WHERE { ?a ?b ?c }")
    (w,) = q.windows
    assert (w.range_param, w.range_ms, w.step_ms) == ("r", None, 1000)
    assert "?r" not in q.var_spans  # the FROM clause is not SPARQL: nothing to substitute there


W = "FROM STREAM <http://s> [RANGE 1s STEP 1s]"


@pytest.mark.parametrize("text, line, column, words", [
    ("REGISTER QUERY q AS SELECT * FROM STREAM <http://s> [RANGE 1s STEP 1s] WHERE { SERVICE <http://x> { ?a ?b ?c } }",
     1, 80, "SERVICE (federated query) is not supported"),
    ("REGISTER QUERY q AS SELECT * WHERE { STREAM <http://s> [RANGE 1s] { ?a ?b ?c } }", 1, 38, "CQELS"),
    ("REGISTER QUERY q AS SELECT * FROM STREAM <http://s> [RANGE 1s SLIDE 1s] WHERE {}", 1, 63, "SLIDE"),
    ("REGISTER QUERY q AS SELECT * FROM STREAM <http://s> [NOW] WHERE {}", 1, 54, "[NOW …] is not supported"),
    ("REGISTER QUERY q AS SELECT * FROM STREAM <http://s> [RANGE TRIPLES 5 STEP 1] WHERE {}", 1, 70,
     "STEP on a count window is not supported"),
    ("REGISTER QUERY q AS PREFIX f: <http://larkc.eu/csparql/sparql/jena/ext#>\nSELECT (f:count(?a) AS ?n) " + W
     + " WHERE { ?a ?b ?c }", 2, 9, "f:count is not supported"),
    ("REGISTER QUERY q AS SELECT * FROM STREAM <http://s> [RANGE 2s STEP 1s]\nFROM STREAM <http://t> [RANGE 4s STEP 2s] "
     "WHERE {}", 2, 13, "different STEPs in one query are not supported"),
    ("REGISTER QUERY q AS SELECT * " + W + " WHERE { WINDOW <http://w> { ?a ?b ?c } }", 1, 87, "no such window"),
    ("REGISTER QUERY q AS SELECT * FROM NAMED WINDOW <w> ON <http://s> [RANGE 1s STEP 1s] WHERE {}", 1, 48,
     "absolute IRI"),
    ("REGISTER ISTREAM q AS SELECT * " + W + " WHERE {}", 1, 10, "REGISTER ISTREAM is not supported"),
    ("REGISTER STREAM q AS SELECT * " + W + " WHERE {}", 1, 22, "REGISTER STREAM needs CONSTRUCT"),
    ("REGISTER QUERY q REPORT SOMETIMES AS SELECT * " + W + " WHERE {}", 1, 25, "unknown report policy"),
    ("REGISTER QUERY q REPORT ON WINDOW CLOSE AND PERIODIC 1s AS SELECT * " + W + " WHERE {}", 1, 45,
     "only one of WINDOW CLOSE"),
    ("REGISTER QUERY q REPORT PERIODIC 1s AS SELECT * FROM STREAM <http://s> [RANGE TRIPLES 3] WHERE {}", 1, 16,
     "REPORT PERIODIC (COMPUTED EVERY) needs a time window"),
    ("REGISTER QUERY q AS SELECT * FROM STREAM <http://s> [RANGE P1M STEP 1s] WHERE {}", 1, 60, "day-time duration"),
    ("REGISTER QUERY q AS SELECT * FROM STREAM <http://s> [RANGE ?r STEP 1s] WHERE {}", 1, 60, "no such parameter"),
    ("REGISTER QUERY q AS SELECT * FROM STREAM <http://s> [RANGE 1s STEP 1s] FROM STREAM <http://s> "
     "[RANGE 2s STEP 1s] WHERE {}", 1, 84, "name them"),
])
def test_unsupported_features_are_named_with_their_position(text, line, column, words):
    with pytest.raises(QueryParseError) as info:
        parse_query(text)
    err = info.value
    assert words in err.message, err.message
    assert (err.line, err.column) == (line, column), err.message
