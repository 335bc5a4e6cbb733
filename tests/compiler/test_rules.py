"""The rule language: parsing, positions, JSON round trip, and context checks."""

from __future__ import annotations

import pytest

from adaptbench.compiler import ast as A
from adaptbench.compiler.rules import RuleSyntaxError, parse_rule

GOOD = [
    "for egg_dish: it is scrambled | omelette",
    "for coffee, tea if available (milk & plant_based): it has no (milk & !plant_based) and sides has milk",
    "for all if task has beverage and task has food: beverage served before food",
    "for egg_dish: count(it, spice) >= 3",
    "for cereal: it adds milk before breakfast_cereal",
    "for coffee: if available espresso_machine then it made in espresso_machine else it made in pour_over",
    "for egg_dish: it has heated cheese and not it has chopped onion",
    "for egg_dish: it cooked in stainless | cast_iron",
    "for egg_dish: uses spatula & silicone",
    "for eggs: made toast",
    "x within cooking_appliance",
    "not (z is x or z within x)",
    "if verb is heating then y within cooking_appliance else true",
]


@pytest.mark.parametrize("text", GOOD)
def test_good_rules_parse_and_round_trip(text):
    rule = parse_rule(text)
    assert A.from_data(A.to_data(rule)) == rule


@pytest.mark.parametrize("text,line,col,fragment", [
    ("for egg_dish it has milk", 1, 14, "unexpected 'it'"),
    ("for coffee: it has (milk | cream", 1, 33, "ends too early"),
    ("for coffee: it has milk &", 1, 26, "ends too early"),
    ("for coffee: it haz milk", 1, 16, "unexpected 'haz'"),
    ("for coffee: count(it, milk) => 2", 1, 29, "unexpected character"),
])
def test_syntax_errors_point_at_the_spot(text, line, col, fragment):
    with pytest.raises(RuleSyntaxError) as exc:
        parse_rule(text)
    assert (exc.value.line, exc.value.col) == (line, col)
    assert fragment in exc.value.message


def test_names_that_start_with_keywords_are_names():
    rule = parse_rule("for eggs: it has hash_brown | heated_thing | isle")
    names = [n.name for n in A.walk(rule) if isinstance(n, A.ClsName)]
    assert names == ["hash_brown", "heated_thing", "isle"]


def test_positions_shift_into_the_file():
    rule = A.shift(parse_rule("for eggs: it has milk"), 9, 10)
    name = next(n for n in A.walk(rule) if isinstance(n, A.ClsName))
    assert (name.line, name.col) == (10, 28)
