"""The answer-use probe (issue 28 item 2, `adapt probe answers`): its pairs of prompts differ only in the
user's answer and the two answers' plans act differently at the probe step; a model that ignores answers
gets the baseline (50% of prompts, 0% of pairs) and a stand-in that follows answers gets 100%."""

from __future__ import annotations

import json
import re

import pytest

from .conftest import SKIP_MODELS

pytestmark = pytest.mark.paper


@pytest.fixture(scope="module")
def pairs(domain):
    from adaptbench.llm.probe import build_pairs

    return build_pairs(domain, tasks=["eggs"], personas=["juan"], seeds=[0])


def _reply(prompt) -> str:
    """The user's last reply in a prompt's messages (what a model is told)."""
    replies = [m for msg in prompt.messages for m in re.findall(r"The user replied: (.*)", msg["content"])]
    return replies[-1]


def _swap(prompt, old: str, new: str) -> tuple:
    return tuple({**m, "content": m["content"].replace(old, new)} for m in prompt.messages)


def test_pairs_differ_only_in_the_answer(pairs):
    assert len(pairs) >= 5
    for p in pairs:
        assert p.a.answer != p.b.answer and p.a.option != p.b.option and p.a.action != p.b.action
        assert p.a.prompt.messages != p.b.prompt.messages
        assert _swap(p.a.prompt, p.a.answer, p.b.answer) == p.b.prompt.messages, p.key()
        assert _reply(p.a.prompt) == p.a.answer and _reply(p.b.prompt) == p.b.answer
        asks = [m for m in p.a.prompt.messages if m["role"] == "assistant" and m["content"] == f'Action: Ask "{p.question}"']
        assert len(asks) == 1  # the question was asked once, before the probe step


def test_pairs_follow_the_domain(pairs, domain):
    """Egg style from `scrambled` (the reading of participles), the option each answer names, and a vegan answer
    that asks for the egg substitute."""
    by_choice = {p.choice: p for p in pairs}
    style = by_choice["eggs.style"]
    assert style.a.option == "scramble" and style.b.option != "scramble"
    base = by_choice["eggs.base"]
    assert (base.a.option, base.b.option) == ("egg", "vegan_egg_substitute")
    assert base.a.action == "Look for egg" and base.b.action == "Look for egg substitute"


def test_reading_of_answers(domain):
    from adaptbench.agents.plans import all_recipes, choice_points
    from adaptbench.llm.probe import asked_for

    points = dict(choice_points(domain, all_recipes(domain, domain.task["eggs"])))
    assert asked_for(domain, points["eggs.style"], "I like my eggs fried.") == "fry"
    assert asked_for(domain, points["eggs.style"], "Poached, please.") == "poach"
    assert "swiss_cheese" in asked_for(domain, points["eggs.fillings"], "Add some lactose-free cheese to my eggs.")
    assert asked_for(domain, points["eggs.style"], "Serve breakfast on the patio.") is None  # not about the choice


def test_the_question_at_the_start(domain):
    from adaptbench.llm.probe import build_pairs

    pairs = build_pairs(domain, tasks=["eggs"], personas=["juan"], seeds=[0], at="start")
    assert pairs
    for p in pairs:
        first = p.a.prompt.messages[2]
        assert first["content"] == f'Action: Ask "{p.question}"'
        assert _swap(p.a.prompt, p.a.answer, p.b.answer) == p.b.prompt.messages


def _follower(pairs):
    """A scripted stand-in that follows answers: it reads the user's reply in the prompt and prefers the action
    that answer's plan takes."""
    wanted = {(p.a.answer, p.a.action, p.b.action): p.a.action for p in pairs}
    wanted |= {(p.b.answer, p.a.action, p.b.action): p.b.action for p in pairs}

    def score(prompt, actions):
        pick = wanted[(_reply(prompt), *actions)]
        return tuple(0.0 if a == pick else -1.0 for a in actions)
    return score


def _ignorer(prompt, actions):
    """A stand-in that ignores the answer: it prefers the shorter action (of two as long, the first in
    alphabetical order), whatever it was told."""
    return tuple(-len(a) - 0.1 * sorted(actions).index(a) for a in actions)


def test_a_follower_gets_everything_and_an_ignorer_the_baseline(pairs):
    from adaptbench.llm.probe import IGNORING_PAIRS, IGNORING_SHARE, probe

    follows = probe(_follower(pairs), pairs)
    assert (follows.share, follows.pair_share) == (1.0, 1.0) and follows.mean_shift == 2.0
    ignores = probe(_ignorer, pairs)
    assert (ignores.share, ignores.pair_share, ignores.mean_shift) == (IGNORING_SHARE, IGNORING_PAIRS, 0.0)


@SKIP_MODELS
def test_a_model_that_does_not_see_the_answer_gets_the_baseline(pairs, backend):
    """The tiny model scoring prompts whose reply is blanked: its two prompts are one, so it follows in exactly one."""
    from adaptbench.llm.probe import Pair, probe

    blank = [Pair(p.task, p.choice, p.question, p.seed, p.step,
                  _blanked(p.a), _blanked(p.b)) for p in pairs]
    result = probe(_model(backend), blank)
    assert (result.share, result.pair_share, result.mean_shift) == (0.5, 0.0, 0.0)
    real = probe(_model(backend), pairs)
    assert real.pairs == len(pairs) and 0.0 <= real.share <= 1.0
    assert all(len(s.under_a) == 2 and all(x < 0 for x in s.under_a + s.under_b) for s in real.scores)


def _model(backend):
    from adaptbench.llm.probe import backend_scorer

    return backend_scorer(backend)


def _blanked(side):
    from dataclasses import replace

    from adaptbench.llm.prompts import Prompt

    msgs = tuple({**m, "content": m["content"].replace(side.answer, "(an answer)")} for m in side.prompt.messages)
    return replace(side, prompt=Prompt(msgs, side.prompt.prefix))


def test_pairs_by_kind(domain, pairs):
    """A pair whose actions differ only in instance numbers is an object choice, any other a named one, and the
    shares by kind add up to the whole."""
    from dataclasses import replace

    from adaptbench.llm.probe import KINDS, probe

    pair = pairs[0]
    obj = replace(pair, a=replace(pair.a, action="Move pan_1 to stove_0"), b=replace(pair.b, action="Move pan_0 to stove_0"))
    named = replace(pair, a=replace(pair.a, action="Look for almond_milk"), b=replace(pair.b, action="Look for milk"))
    assert (obj.kind, named.kind) == ("object", "named")
    mixed = [obj, named, named]
    result = probe(_follower(mixed), mixed)
    parts = result.by_kind()
    assert list(parts) == list(KINDS) and [r.pairs for r in parts.values()] == [2, 1]
    assert sum(r.prompts_followed for r in parts.values()) == result.prompts_followed == 6
    summary = result.summary()
    assert summary["by_kind"]["object"]["pairs"] == 1 and "by_kind" not in summary["by_kind"]["named"]


def test_spread_keeps_every_part():
    from adaptbench.llm.probe import spread

    assert spread(list(range(10)), 5) == [0, 2, 4, 6, 8]
    assert spread(list(range(3)), 5) == [0, 1, 2] and spread(list(range(3)), 0) == [0, 1, 2]


@SKIP_MODELS
def test_cli_json_and_table(tiny, capsys):
    from adaptbench.cli.main import main

    args = ["probe", "answers", "--model", str(tiny), "--tasks", "eggs", "--personas", "juan", "--limit", "3", "--quiet"]
    assert main([*args, "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["pairs"] == 3 and [r["model"] for r in data["models"]] == [str(tiny)]
    row = data["models"][0]
    assert row["ignoring_share"] == 0.5 and row["ignoring_pair_share"] == 0.0 and 0 <= row["share"] <= 1
    assert main(args) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].startswith("model") and lines[2].startswith(str(tiny)) and "50.0%" in lines[2]
    assert {k for k in row["by_kind"]} <= {"named", "object"} and sum(p["pairs"] for p in row["by_kind"].values()) == 3
    assert all(line.startswith("  ") and "choices" in line for line in lines[3:])


def test_cli_unknown_model_is_one_line(capsys, tmp_path):
    from adaptbench.cli.main import main

    assert main(["probe", "answers", "--model", str(tmp_path / "nope")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nope: no such model directory" in err[0]
    assert main(["probe", "answers", "--model", "student", "--limit", "-1"]) == 2
    assert "--limit must be 0" in capsys.readouterr().err
