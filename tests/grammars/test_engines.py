"""python-lark and llguidance accept and reject the same strings under the same generated grammar."""

from __future__ import annotations

import random

import pytest

from adaptbench.grammars import StateGrammar, build_base, build_index
from adaptbench.grammars.parse import lark_parser, parse
from adaptbench.grammars.sample import sample
from adaptbench.runtime.env import Env

from .conftest import LLAcceptor, read_example

_BREAKERS = [
    lambda s, r: s.replace(" ", "  ", 1), lambda s, r: s + " ", lambda s, r: " " + s, lambda s, r: s + ".",
    lambda s, r: "Action: " + s, lambda s, r: s.lower(), lambda s, r: s.upper(),
    lambda s, r: s.rsplit(" ", 1)[0], lambda s, r: s.replace("_", "-"), lambda s, r: s + " now",
    lambda s, r: s.replace(" ", "\t", 1), lambda s, r: s[: r.randint(1, max(1, len(s) - 1))],
    lambda s, r: s + "0", lambda s, r: s.replace(s.split(" ")[-1], "Unseen_9"),
]
_FIXED_INVALID = ["", " ", "Ask", 'Ask ""', 'Ask "a"b"', "Ask hello", 'Ask "line\nbreak"', "Declare done",
                  "frobnicate items in pan_0 to get x", "Chop pan_0 to get X", "Mix all items in pan_0 to get 9x",
                  "Look for", "Look for  eggs", "Look for eggs ", "Turn on", "Move to pan_0"]


@pytest.fixture(scope="module")
def domain(small_domain):
    """Engine test: the small test spec (tests/spec_small), not the paper's."""
    return small_domain


@pytest.fixture(scope="module")
def index(domain):
    return build_index(domain)


def _corpus(index, observed, level, rng) -> tuple[list, list]:
    valid = sorted({sample(index, observed, rng, level)[0] for _ in range(420)})
    invalid = [b(s, rng) for s in valid[::2] for b in rng.sample(_BREAKERS, 2)] + _FIXED_INVALID
    return valid, sorted(set(invalid) - set(valid))


@pytest.fixture(scope="module")
def observed(domain):
    env = Env(domain, "eggs", seed=None, full_scene=True)
    env.reset()
    for text in read_example("fifty_steps.txt")[:30]:
        env.step(text)
    return env.observed()


@pytest.mark.parametrize("level, variant", [("observed", "default"), ("typed", "default"), ("syntax", "default"),
                                            ("observed", "never_ask")])
def test_lark_and_llguidance_agree(index, observed, lltok, level, variant):
    rng = random.Random(f"{level}-{variant}")
    text = StateGrammar(build_base(index, level, variant), observed).text
    parser, ll = lark_parser(text), LLAcceptor(lltok, text)
    valid, invalid = _corpus(index, observed, level, rng)
    if variant == "never_ask":
        invalid += [s for s in valid if s.startswith("Ask ")]
        valid = [s for s in valid if not s.startswith("Ask ")]
    disagree = [(s, lk) for s in valid + invalid if (lk := parse(parser, index, s) is not None) != ll.accepts(s)]
    assert disagree == []
    assert len(valid) >= 300 and all(ll.accepts(s) for s in valid)
    rejected = [s for s in invalid if not ll.accepts(s)]
    assert len(rejected) >= 200, f"only {len(rejected)} of {len(invalid)} broken strings are rejected"


@pytest.mark.parametrize("contents", [True, False])
def test_every_level_and_variant_compiles_cleanly_in_llguidance(index, lltok, contents):
    """No errors and no warnings, including the typed level with no content observed yet."""
    import llguidance

    from adaptbench.grammars import LEVELS, VARIANTS, Observed

    obs = Observed(frozenset(index.layout), frozenset(index.layout_contents) if contents else frozenset())
    for level in LEVELS:
        for variant in VARIANTS:
            grammar = llguidance.LLMatcher.grammar_from_lark(StateGrammar(build_base(index, level, variant), obs).text)
            assert llguidance.LLMatcher.validate_grammar_with_warnings(grammar, lltok) == (False, []), (level, variant)


def test_typed_level_without_contents_drops_pour(index):
    from adaptbench.grammars import Observed

    text = StateGrammar(build_base(index, "typed"), Observed(frozenset(index.layout), frozenset())).text
    parser = lark_parser(text)
    assert "pour" not in text.split("\n")[3] and "CONTENT" not in text
    assert parse(parser, index, "Move pan_9 to table_0") is None
    assert parse(parser, index, "Search table_0").action == "search"
