"""The regex reading of the structural grammar (what the compiler checks recipe steps with) accepts
exactly what the simulator's lark parser accepts, with the same action and slots."""

from __future__ import annotations

import re

import pytest

from adaptbench.grammars.match import FormMatcher
from adaptbench.runtime.index import runtime_index

_VAR = re.compile(r"\{(src:)?(\w+)\}")


def _steps(steps):
    for s in steps:
        if s.kind == "do":
            yield s.text
        else:
            yield from _steps(s.body)


@pytest.fixture(scope="module")
def both(domain):
    ix = runtime_index(domain)
    return FormMatcher(ix.grammar.actions), ix.parser


def _texts(domain) -> list:
    """Every shipped recipe step with its placeholders filled, and broken variants of each."""
    out = set()
    for r in domain.recipes:
        for text in _steps(r.steps):
            if text.startswith("ADD "):
                continue
            filled = _VAR.sub(lambda m: m.group(2) + "_0", text)
            out |= {filled, filled.lower(), filled.replace(" to ", " too "), filled + " now", "Cok " + filled,
                    filled.replace(" ", "  ", 1), filled.replace("_0", "-0"), filled.capitalize()}
    out |= {"Declare Done", 'Ask "How do you like your eggs?"', "Look for peanut butter", "chop x_0 to get y",
            "Chop the object x to get y", "heat the object x to get y", "Heat pan_0", "Serve the object a at b",
            "Place a on b", "Mix all items in bowl_0 to get batter", "cook items in pan_0 to get e", ""}
    return sorted(out)


def test_matcher_agrees_with_the_parser(domain, both):
    matcher, parser = both
    texts = _texts(domain)
    assert len(texts) > 300
    for text in texts:
        mine, theirs = matcher.match(text), parser.parse(text)
        assert (mine is None) == (theirs is None), text
        if mine is not None:
            assert (mine.action, mine.slots) == (theirs.action, theirs.slots), text
