"""Words -> the Utterance the rules read, the menu from the ontology, the grammar, pronunciations:
plain Python, no JVM."""

from __future__ import annotations

import pytest

from gateway.config import PROJECT_ROOT
from gateway.dialogue.grammar import build, spell_out
from gateway.dialogue.menu import Drink, Menu, parse_pronunciations, plural, read_menu
from gateway.dialogue.words import hear, tokens

TTL = (PROJECT_ROOT / "ontology" / "teahouse.ttl").read_text(encoding="utf-8")
BASE = "http://printeps.org/cafe/entrance/"


@pytest.fixture(scope="module")
def menu() -> Menu:
    return read_menu(TTL, BASE)


def test_the_menu_is_every_beverage_with_its_words(menu):
    by_name = {d.individual: d for d in menu.drinks}
    assert {"greenTea", "coffee", "matcha", "hojicha", "blackTea", "orangeJuice"} <= set(by_name)
    assert by_name["greenTea"].forms == ("green tea", "green teas")
    assert dict(by_name["hojicha"].pronunciations)["hojicha"] == "HH OW JH IY CH AH | HH AA JH IH CH AH"


@pytest.mark.parametrize("said, shape, drink, count", [
    ("Can I have two green teas, please?", "can i have NUMBER DRINK please", "green tea", 2),
    ("a coffee", "NUMBER DRINK", "coffee", 1),
    ("An orange juice", "NUMBER DRINK", "orange juice", 1),
    ("I'd like 3 matchas", "i'd like NUMBER DRINK", "matcha", 3),
    ("no, make that coffee", "no make that DRINK", "coffee", 0),
    ("a table for two", "a table for NUMBER", None, 2),  # "a" is a number only before a drink
    ("tea", "tea", None, 0),  # "tea" alone is no drink of the menu
    ("", "", None, 0),
    ("100 coffees", "100 DRINK", "coffee", 0),  # beyond 99 is no number of cups
])
def test_hear_marks_drinks_and_numbers(menu, said, shape, drink, count):
    heard = hear(said, menu)
    assert heard.shape == shape
    assert (heard.drink.label if heard.drink else None) == drink
    assert heard.count == count


def test_the_longest_name_wins():
    menu = Menu((Drink("tea", "tea", "teas"), Drink("greenTea", "green tea", "green teas")))
    assert hear("green tea and tea", menu).shape == "DRINK and DRINK"
    assert hear("green tea and tea", menu).drink.individual == "greenTea"


def test_tokens_keep_apostrophes_inside_words():
    assert tokens("I’d like THAT'S it!") == ["i'd", "like", "that's", "it"]


def test_plurals_and_pronunciations():
    assert [plural(w) for w in ("tea", "glass", "berry", "day")] == ["teas", "glasses", "berries", "days"]
    assert parse_pronunciations("yuzu: y uw z uw ; bad ; : X") == (("yuzu", "Y UW Z UW"),)
    assert spell_out("yuzu") == "Y UW Z UW"
    assert spell_out("coffee") == "K OW F IY"


def test_the_grammar_has_every_sentence_and_drink(menu):
    files = {"understanding.dslr": '''
rule "Order" when
    The customer says "NUMBER DRINK"
then
    The customer means "order"
end
rule "Politeness" when
    The customer says "Please"
then
    The words carry no meaning
end
'''}
    grammar = build(files, menu)
    assert "public <utterance> = [<filler>] <meaning> [<filler>];" in grammar.jsgf
    assert "<meaning> = (<count> <drink>);" in grammar.jsgf
    assert "<filler> = (please);" in grammar.jsgf
    assert "orange juices" in grammar.jsgf and "please" in grammar.words and "juices" in grammar.words
