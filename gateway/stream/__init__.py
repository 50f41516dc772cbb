"""Stream reasoning: C-SPARQL continuous queries over timestamped RDF streams (see docs/streams.md)."""

from gateway.stream.engine import QueryNotFound, StreamEngine, StreamError
from gateway.stream.lexer import QueryParseError
from gateway.stream.params import OntologySource, ParamError
from gateway.stream.query import ContinuousQuery, ParamSpec, WindowSpec, parse_query
from gateway.stream.rules import BindingError, RuleBinding

__all__ = [
    "BindingError", "ContinuousQuery", "OntologySource", "ParamError", "ParamSpec", "QueryNotFound",
    "QueryParseError", "RuleBinding", "StreamEngine", "StreamError", "WindowSpec", "parse_query",
]
