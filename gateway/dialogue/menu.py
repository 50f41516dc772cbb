"""The menu: every ``Beverage`` individual of the ontology, with how customers name it.

Why from the ontology: the owner adds a drink in the Knowledge view (an individual with its
``rdfs:label``) and it can be ordered at once, by text and by voice — the words, the grammar and
the dialogue rules never list drinks themselves. Read with rdflib, once per ontology text.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import lru_cache

BEVERAGE = "Beverage"
_SPACES = re.compile(r"\s+")


@dataclass(frozen=True)
class Drink:
    """One drink: its individual, its label (what Pepper says) and the words customers use."""

    individual: str
    label: str
    plural: str
    pronunciations: tuple[tuple[str, str], ...] = ()  # (word, CMU phones) the ontology gives

    @property
    def forms(self) -> tuple[str, ...]:
        """How a customer may name it: the label and the plural, in lower case."""
        return tuple(dict.fromkeys((self.label, self.plural)))


@dataclass(frozen=True)
class Menu:
    drinks: tuple[Drink, ...] = field(default_factory=tuple)

    def by_form(self) -> dict[tuple[str, ...], Drink]:
        """Each way of naming a drink as a tuple of words -> the drink."""
        return {tuple(form.split()): d for d in self.drinks for form in d.forms}

    def words(self) -> set[str]:
        return {w for d in self.drinks for form in d.forms for w in form.split()}

    def pronunciations(self) -> dict[str, str]:
        return {w: p for d in self.drinks for w, p in d.pronunciations}

    def plural_of(self, label: str) -> str:
        return next((d.plural for d in self.drinks if d.label == label), plural(label))


def normal(text: str) -> str:
    return _SPACES.sub(" ", text.strip().lower())


def plural(label: str) -> str:
    """English plural of the last word (for a drink the ontology gives no plural)."""
    if not label:
        return label
    if label.endswith(("s", "x", "ch", "sh")):
        return label + "es"
    if label.endswith("y") and label[-2:-1] not in "aeiou":
        return label[:-1] + "ies"
    return label + "s"


def parse_pronunciations(text: str) -> tuple[tuple[str, str], ...]:
    """``"matcha: M AA CH AH | M AE CH AH; matchas: M AA CH AH Z"`` -> ((word, phones), ...), with
    `` | `` between a word's alternative pronunciations; bad parts skipped."""
    out = []
    for part in text.split(";"):
        word, sep, phones = part.partition(":")
        if sep and word.strip() and phones.strip():
            alternatives = [" ".join(p.split()).upper() for p in phones.split("|") if p.strip()]
            out.append((normal(word), " | ".join(alternatives)))
    return tuple(out)


@lru_cache(maxsize=4)
def read_menu(ontology_text: str, base: str, turtle: bool = True) -> Menu:
    """Every individual of class ``Beverage`` (or a subclass), by label; individuals without a
    label are named by their local name with spaces before capitals (``oolongTea`` -> "oolong tea")."""
    import rdflib

    graph = rdflib.Graph()
    graph.parse(data=ontology_text, format="turtle" if turtle else "xml")
    beverage = rdflib.URIRef(base + BEVERAGE)
    classes = {beverage} | set(graph.transitive_subjects(rdflib.RDFS.subClassOf, beverage))
    ns = rdflib.Namespace(base)
    drinks = []
    for cls in classes:
        for ind in graph.subjects(rdflib.RDF.type, cls):
            name = str(ind)[len(base):] if str(ind).startswith(base) else str(ind).rsplit("#", 1)[-1]
            label = normal(str(next(graph.objects(ind, rdflib.RDFS.label), "")) or re.sub(r"(?<!^)([A-Z])", r" \1", name))
            given = normal(str(next(graph.objects(ind, ns.plural), "")))
            said = parse_pronunciations(str(next(graph.objects(ind, ns.pronunciation), "")))
            drinks.append(Drink(name, label, given or plural(label), said))
    return Menu(tuple(sorted(drinks, key=lambda d: d.individual)))
