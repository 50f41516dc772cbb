"""The teahouse ontology: OWL + SWRL reasoning with Pellet kept warm in the JVM (docs/ontology.md)."""

from gateway.ontology.reasoner import Reasoner, ReasonerError

__all__ = ["Reasoner", "ReasonerError"]
