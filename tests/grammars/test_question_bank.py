"""The `bank` question set: an `Ask` names one of the domain's own questions, in python-lark and llguidance
alike, and nothing else in the grammar changes."""

from __future__ import annotations

import pytest

from adaptbench.grammars import GrammarCache, Observed, StateGrammar, build_base
from adaptbench.grammars.emit import QUESTION, question_terminal
from adaptbench.grammars.index import domain_questions
from adaptbench.grammars.parse import lark_parser, parse

from .conftest import LLAcceptor


def _observed(index) -> Observed:
    return Observed(frozenset(index.layout) | {"pan_0", "egg_0"}, frozenset(index.layout_contents))


def test_the_bank_is_every_question_the_domains_choices_ask(domain, index):
    asked = {c.ask for c in domain.planning if c.ask} | {c.ask for r in domain.recipes for c in r.choices if c.ask}
    assert index.questions == domain_questions(domain) == tuple(sorted(asked))
    assert len(index.questions) >= 30 and "Where would you like to have breakfast?" in index.questions


@pytest.mark.parametrize("variant", ["default", "ask_only"])
def test_a_bank_grammar_takes_the_domains_questions_and_nothing_else(index, variant):
    parser = lark_parser(StateGrammar(build_base(index, "observed", variant, questions="bank"), _observed(index)).text)
    for q in index.questions:
        got = parse(parser, index, f'Ask "{q}"')
        assert got is not None and got.action == "ask", q
    q = index.questions[0]
    for text in ('Ask "Scrambled or fried?"', f'Ask "{q[:-1]}"', f'Ask "{q} "', f'Ask "{q}?"', f"Ask {q}"):
        assert parse(parser, index, text) is None, text
    assert (parse(parser, index, "Move egg_0 to pan_0") is not None) == (variant == "default")


def test_bank_and_free_grammars_differ_only_in_the_question_terminal(index):
    free = StateGrammar(build_base(index), _observed(index)).text.splitlines()
    bank = StateGrammar(build_base(index, questions="bank"), _observed(index)).text.splitlines()
    changed = [i for i, (a, b) in enumerate(zip(free, bank, strict=True)) if a != b]
    at = free.index(f"QUESTION: {QUESTION}")
    assert changed == [1, at]  # the header's second line says so, and the QUESTION terminal is the bank
    assert bank[1] == free[1].replace(" · variant default", " · variant default · questions bank")
    assert bank[at] == f"QUESTION: {question_terminal(index, 'bank')}"


def test_the_cache_keeps_free_and_bank_apart(index):
    cache = GrammarCache(index)
    assert cache.base("eggs", questions="bank") is cache.base("eggs", questions="bank")
    assert cache.base("eggs", questions="bank") is not cache.base("eggs")
    assert cache.base("eggs").questions == "free" and cache.base("eggs", questions="bank").questions == "bank"


def test_an_unknown_question_set_is_refused(index):
    with pytest.raises(ValueError, match="unknown question set 'any'.*free, bank"):
        build_base(index, questions="any")


def test_llguidance_accepts_exactly_the_bank(index, lltok):
    text = StateGrammar(build_base(index, "observed", questions="bank"), _observed(index)).text
    ll = LLAcceptor(lltok, text)
    assert all(ll.accepts(f'Ask "{q}"') for q in index.questions)
    assert not ll.accepts('Ask "Scrambled or fried?"') and not ll.accepts(f'Ask "{index.questions[0][:-1]}"')
    assert ll.accepts("Move egg_0 to pan_0")
