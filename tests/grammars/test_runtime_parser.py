"""The simulator's parser (structural grammar, lark Earley, cached by text) against the regex matcher
the runtime used before (kept only as this test's oracle): the same action and slots on every fixture
and example action, every action of scripted recipe runs, and strings sampled from the grammar."""

from __future__ import annotations

import random

import pytest
from lark import Lark, Tree

from adaptbench.agents.normalise import normalise
from adaptbench.agents.scripted import play
from adaptbench.agents.users import OfflineUser
from adaptbench.grammars.parser import keyword_collisions
from adaptbench.grammars.sample import sample
from adaptbench.runtime.actions import compile_templates, match
from adaptbench.runtime.env import Env
from adaptbench.runtime.index import runtime_index


@pytest.fixture(scope="module")
def templates(domain):
    return compile_templates(domain)


@pytest.fixture(scope="module")
def parser(domain):
    return runtime_index(domain).parser


def _oracle(templates, text):
    hit = match(templates, text)
    return None if hit is None else (hit[0].id, hit[1])


def _ours(parser, text):
    got = parser.parse(text)
    return None if got is None else (got.action, got.args)


def test_every_fixture_action_parses_as_the_regex_path_read_it(parser, templates, states):
    seen = 0
    for label, _, _, actions in states:
        for text in actions:
            assert _ours(parser, text) == _oracle(templates, text) != None, f"{label}: '{text}'"  # noqa: E711
            seen += 1
    assert seen > 2000


@pytest.mark.parametrize("agent", ["never-ask", "always-ask"])
def test_recipe_runs_parse_as_the_regex_path_read_them(domain, parser, templates, agent):
    texts = set()
    for task in domain.task:
        persona = next(iter(domain.persona))
        env = Env(domain, task, persona=persona, seed=1,
                  user=OfflineUser(domain, domain.persona[persona], domain.task[task]))
        play(agent, env)
        texts |= {e.text for e in env.world.trace}
    assert len(texts) > 50
    for text in sorted(texts):
        assert _ours(parser, text) == _oracle(templates, text) != None, text  # noqa: E711


@pytest.mark.parametrize("level", ["syntax", "observed", "typed"])
def test_sampled_strings_parse_as_sampled(index, parser, states, level):
    rng = random.Random(5)
    observed = states[-1][2]
    for _ in range(500):
        text, action, slots = sample(index, observed, rng, level)
        assert _ours(parser, text) == (action, slots), text


def test_the_structural_grammar_reads_every_string_one_way(index, parser, states):
    ambiguous = Lark(parser.text, parser="earley", lexer="dynamic", ambiguity="explicit")
    rng = random.Random(2)
    corpus = {a for _, _, _, actions in states[::7] for a in actions}
    corpus |= {sample(index, states[-1][2], rng, "syntax")[0] for _ in range(200)}
    corpus |= {"zorp items in bowl_0 to get x", "cook items in pan_0 to get x", "Cook items in pan_0 to get x",
               "Chop egg_0 to get y", "chop egg_0 to get y", "Heat egg_0 to get y"}
    for s in sorted(corpus):
        tree = ambiguous.parse(s)
        assert not any(isinstance(t, Tree) and t.data == "_ambig" for t in tree.iter_subtrees()), s


def test_keyword_verb_readings_are_explicit(index, parser):
    assert keyword_collisions(index) == {("freeform_items", 0): ["Cook"], ("freeform_object", 0): [],
                                         ("freeform_object", 1): ["Chop", "chop"]}
    assert _ours(parser, "chop the object egg_0 to get x")[0] == "freeform_object"
    assert _ours(parser, "Chop egg_0 to get y")[0] == "chop"
    assert _ours(parser, "chop egg_0 to get y")[0] == "chop"
    assert _ours(parser, "Cook items in pan_0 to get x")[0] == "cook"
    assert _ours(parser, "cook items in pan_0 to get x")[0] == "freeform_items"  # then: not a verb I know
    assert _ours(parser, "Heat pan_0") == ("heat", {"x": "pan_0"})
    assert _ours(parser, "heat egg_0 to get x")[0] == "freeform_object"
    assert _ours(parser, "Mix all items in bowl_0 to get m")[0] == "mix"
    assert _ours(parser, "mix items in bowl_0 to get m")[0] == "freeform_items"
    assert _ours(parser, "Serve the object egg_0 at table_1")[0] == "move"


def test_unknown_words_reach_binding_with_their_helpful_messages(domain):
    env = Env(domain, "eggs", seed=0)
    env.reset()
    assert "is not a verb I know" in env.step("zorp items in bowl_0 to get x").observation
    assert "that you have found" in env.step("Move egg_99 to table_1").observation
    assert env.step("move egg_0 to table_1").observation.startswith("I don't understand")


def test_parses_are_cached_per_domain_index(domain, parser):
    parser.parse("Look for eggs")
    before = parser.cache_info().hits
    parser.parse("Look for eggs")
    assert parser.cache_info().hits == before + 1
    assert runtime_index(domain) is runtime_index(domain)
    assert Env(domain, "eggs").index is runtime_index(domain)


@pytest.mark.parametrize("raw, clean", [
    ("Action: Look for eggs.", "Look for eggs"),
    ("  action:   Move  egg_0 to   pan_0..\nmore text", "Move egg_0 to pan_0"),
    ('Ask "Scrambled or fried?"', 'Ask "Scrambled or fried?"'),
    ("\n\nDeclare Done", "Declare Done"),
])
def test_normalise_model_output_on_the_agent_side(raw, clean):
    assert normalise(raw) == clean
