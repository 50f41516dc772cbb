"""What the customer said -> the words the dialogue rules read (one ``Utterance`` fact).

Why this much in Python and no more: spelling (case, punctuation), numbers ("two", "2", "a" before
a drink) and finding the menu's drinks in the words are the same for every sentence and come from
the ontology; what the words *mean* is left to the understanding rules, which the owner reads and
edits. The rules see ``shape``: the words with every drink replaced by ``DRINK`` and every number
by ``NUMBER`` ("can I have two green teas, please" -> "can i have NUMBER DRINK please"), and what
they stood for in ``drink`` and ``count``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from gateway.dialogue.menu import Drink, Menu

DRINK, NUMBER = "DRINK", "NUMBER"
NUMBER_WORDS = {
    "one": 1, "two": 2, "three": 3, "four": 4, "five": 5, "six": 6, "seven": 7, "eight": 8, "nine": 9,
    "ten": 10, "eleven": 11, "twelve": 12, "thirteen": 13, "fourteen": 14, "fifteen": 15, "sixteen": 16,
    "seventeen": 17, "eighteen": 18, "nineteen": 19, "twenty": 20,
}
ARTICLES = {"a": 1, "an": 1}  # a number only right before a drink: "a coffee"
MAX_COUNT = 99
_TOKEN = re.compile(r"[a-z0-9]+(?:'[a-z]+)?")


@dataclass(frozen=True)
class Heard:
    """One turn's words as the rules see them."""

    text: str  # the words, lower case, single spaces
    shape: str
    drink: Drink | None
    count: int  # 0: no number said

    def fact(self, conversation: str, turn: int) -> dict[str, object]:
        return {"type": "Utterance", "id": f"{conversation}#{turn}", "conversation": conversation, "turn": turn,
                "text": self.text, "shape": self.shape, "drink": self.drink.label if self.drink else "",
                "count": self.count, "handled": False, "answered": False}


def tokens(text: str) -> list[str]:
    """Lower-case words; punctuation is dropped, apostrophes inside words kept ("i'd")."""
    return _TOKEN.findall(text.lower().replace("\u2019", "'"))


def number_of(token: str) -> int | None:
    if token.isdigit():
        value = int(token)
        return value if 0 < value <= MAX_COUNT else None
    return NUMBER_WORDS.get(token)


def hear(text: str, menu: Menu) -> Heard:
    """The words of ``text`` with the menu's drinks and the numbers marked (first of each kept)."""
    words = tokens(text)
    forms = sorted(menu.by_form().items(), key=lambda item: -len(item[0]))
    shape: list[str] = []
    drink: Drink | None = None
    count = 0
    i = 0
    while i < len(words):
        found = next(((form, d) for form, d in forms if tuple(words[i:i + len(form)]) == form), None)
        if found is not None:
            shape.append(DRINK)
            drink = drink or found[1]
            i += len(found[0])
            continue
        value = number_of(words[i])
        if value is None and words[i] in ARTICLES and _drink_at(words, i + 1, forms):
            value = ARTICLES[words[i]]
        if value is not None:
            shape.append(NUMBER)
            count = count or value
        else:
            shape.append(words[i])
        i += 1
    return Heard(" ".join(words), " ".join(shape), drink, count)


def _drink_at(words: list[str], i: int, forms: list[tuple[tuple[str, ...], Drink]]) -> bool:
    return any(tuple(words[i:i + len(form)]) == form for form, _ in forms)
