"""RDF terms and the message → RDF mapping (see ``docs/streams.md``)."""

from gateway.rdf.mapping import Mapper, MappingError, NodeMap, message_to_dict
from gateway.rdf.terms import (
    DEFAULT_PREFIXES,
    PRINTEPS,
    Term,
    TermError,
    Triple,
    canonical_term,
    parse_triple,
    term_from_sparql_json,
    term_to_json,
    term_to_sparql_json,
)

__all__ = [
    "DEFAULT_PREFIXES", "Mapper", "MappingError", "NodeMap", "PRINTEPS", "Term",
    "TermError", "Triple", "canonical_term", "message_to_dict", "parse_triple", "term_from_sparql_json",
    "term_to_json", "term_to_sparql_json",
]
