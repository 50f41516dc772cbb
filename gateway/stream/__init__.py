"""Stream reasoning: C-SPARQL / RSP-QL continuous queries over timestamped RDF streams (see docs/streams.md)."""

from gateway.stream.engine import QueryNotFound, StreamEngine, StreamError
from gateway.stream.lexer import QueryParseError
from gateway.stream.params import OntologySource, ParamError
from gateway.stream.query import (
    ContinuousQuery,
    ParamSpec,
    ReportPolicy,
    WindowSpec,
    parse_query,
)
from gateway.stream.results import ResultEvent, report_to_sparql_json, to_sparql_json
from gateway.stream.rules import BindingError, RuleBinding

__all__ = [
    "BindingError", "ContinuousQuery", "OntologySource", "ParamError", "ParamSpec", "QueryNotFound",
    "QueryParseError", "ReportPolicy", "ResultEvent", "RuleBinding", "StreamEngine", "StreamError", "WindowSpec",
    "parse_query", "report_to_sparql_json", "to_sparql_json",
]
