"""The speech recogniser's grammar, made from the understanding rules' sentences and the menu.

Why generated: a recogniser that listens for anything hears "to read the league" for "two green
teas" (an open language model on synthetic speech); one that listens only for what the rules can
understand is fast and right. So the sentences the owner writes (``The customer says "NUMBER
DRINK"``) and the drinks of the ontology *are* the grammar: change either and the recogniser
follows. A word the recogniser's dictionary lacks (a new drink's name) gets the pronunciation the
ontology gives (``printeps:pronunciation``) or one spelled out from its letters.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from gateway.dialogue.menu import Menu
from gateway.dialogue.words import ARTICLES, DRINK, NUMBER, NUMBER_WORDS, tokens

_RULE = re.compile(r'^\s*rule\s+"(?:[^"\\]|\\.)*".*?^\s*end\b', re.MULTILINE | re.DOTALL)
_SAYS = re.compile(r'^\s*The customer says "([^"]+)"', re.MULTILINE)
FILLER_MARK = "The words carry no meaning"


@dataclass(frozen=True)
class Grammar:
    """A JSGF grammar and the words it uses (with the pronunciations the ontology gives)."""

    jsgf: str
    words: frozenset[str]
    given: tuple[tuple[str, str], ...]  # (word, phones) from the ontology

    @property
    def key(self) -> int:
        return hash((self.jsgf, self.given))


def sentences(files: dict[str, str]) -> tuple[list[str], list[str]]:
    """(meaningful sentences, filler sentences) of the ``.dslr`` files, in the order written."""
    meaning: list[str] = []
    fillers: list[str] = []
    for name in sorted(files):
        if not name.endswith(".dslr"):
            continue
        for block in _RULE.finditer(files[name]):
            text = block.group(0)
            target = fillers if FILLER_MARK in text else meaning
            for said in _SAYS.findall(text):
                words = " ".join(w if w in (DRINK, NUMBER) else w.lower() for w in said.split())
                if words not in target:
                    target.append(words)
    return meaning, fillers


def build(files: dict[str, str], menu: Menu) -> Grammar:
    """The JSGF grammar: ``[<filler>] <meaning> [<filler>]`` over the rules' sentences (one
    meaning per utterance: repetitions (``<meaning>+``) made decoding 3-30x slower and less
    accurate on espeak-ng voices, see docs/benchmarks.md)."""
    meaning, fillers = sentences(files)
    if not meaning:
        meaning = [f"{NUMBER} {DRINK}", DRINK]
    drinks = sorted({form for d in menu.drinks for form in d.forms})
    lines = ["#JSGF V1.0;", "grammar dialogue;",
             "public <utterance> = " + ("[<filler>] <meaning> [<filler>]" if fillers else "<meaning>") + ";",
             "<meaning> = " + " | ".join(_alternative(s) for s in meaning) + ";"]
    if fillers:
        lines.append("<filler> = " + " | ".join(_alternative(s) for s in fillers) + ";")
    lines.append("<number> = " + " | ".join(NUMBER_WORDS) + ";")
    lines.append("<count> = <number> | " + " | ".join(ARTICLES) + ";")
    lines.append("<drink> = " + (" | ".join(_words(d) for d in drinks) or "tea") + ";")
    text = "\n".join(lines) + "\n"
    used = {w for w in re.findall(r"(?<![<\w])[a-z][a-z0-9']*(?![\w>])", "\n".join(lines[3:]))}
    return Grammar(text, frozenset(used), tuple(sorted(menu.pronunciations().items())))


def _alternative(sentence: str) -> str:
    words = sentence.split()
    out = []
    for i, w in enumerate(words):
        if w == DRINK:
            out.append("<drink>")
        elif w == NUMBER:
            out.append("<count>" if i + 1 < len(words) and words[i + 1] == DRINK else "<number>")
        else:
            out.extend(tokens(w))
    return "(" + " ".join(out) + ")" if out else "(<drink>)"


def _words(form: str) -> str:
    return " ".join(tokens(form))


# ---------------------------------------------------------------- pronunciations of unknown words

_DIGRAPHS = {"ch": "CH", "sh": "SH", "th": "TH", "ph": "F", "ng": "NG", "ck": "K", "qu": "K W", "oo": "UW",
             "ee": "IY", "ea": "IY", "ai": "EY", "ay": "EY", "oa": "OW", "ou": "AW", "ow": "OW", "oi": "OY",
             "au": "AO", "ie": "IY"}
_LETTERS = {"a": "AA", "b": "B", "c": "K", "d": "D", "e": "EH", "f": "F", "g": "G", "h": "HH", "i": "IY", "j": "JH",
            "k": "K", "l": "L", "m": "M", "n": "N", "o": "OW", "p": "P", "q": "K", "r": "R", "s": "S", "t": "T",
            "u": "UW", "v": "V", "w": "W", "x": "K S", "y": "IY", "z": "Z"}


def spell_out(word: str) -> str:
    """A rough pronunciation (CMU phones) from the letters of a word the dictionary lacks; good
    enough for a grammar, where the word only competes with the few others it allows. A drink
    that is misheard gets an exact one in the ontology (``printeps:pronunciation``)."""
    letters = re.sub(r"[^a-z]", "", word.lower())
    if len(letters) > 3 and letters.endswith("e") and letters[-2] not in "aeiou":
        letters = letters[:-1]  # silent final e
    phones: list[str] = []
    i = 0
    while i < len(letters):
        pair = letters[i:i + 2]
        if pair in _DIGRAPHS:
            phones.append(_DIGRAPHS[pair])
            i += 2
            continue
        if letters[i] == letters[i - 1:i]:  # a doubled consonant is said once
            i += 1
            continue
        phones.append("Y" if letters[i] == "y" and i == 0 else _LETTERS[letters[i]])
        i += 1
    return " ".join(phones) or "AH"
