"""Every id the observation prints can be used in the next action (issue 6, item 10).

Rollouts of the scripted agents on a few scenes are replayed step by step; after each step, every object
id printed (the layout, `Found ...`, `Opened ...`, `... contains ...`) must be one the parser binds, and
every content listed after `contains` must be nameable too.
"""

from __future__ import annotations

import re

import pytest

from adaptbench.agents.scripted import play
from adaptbench.runtime.actions import ActionFailed, _bind_one
from adaptbench.runtime.env import Env

_WORD = re.compile(r"\b[a-z][a-z0-9_]*\b")
_CONTAINS = re.compile(r"contains ([a-z0-9_]+(?:, [a-z0-9_]+)*)")

CASES = [("oracle", "nalini", "tea_eggs", 0), ("oracle", "jamal", "toast_coffee", 1),
         ("oracle", "maya", "cereal_coffee", 2), ("oracle", "lisa", "eggs", 3),
         ("always-ask", "ron", "tea_toast", 4), ("never-ask", "juan", "eggs", 5)]


def _unbound(world, text: str) -> list:
    """Printed ids and listed contents the parser would refuse."""
    bad = []
    for word in set(_WORD.findall(text)):
        if word in world.specs:
            try:
                _bind_one(world, "entity", word)
            except ActionFailed:
                bad.append(word)
    for group in _CONTAINS.findall(text):
        for name in group.split(", "):
            try:
                _bind_one(world, "content", name)
            except ActionFailed:
                bad.append(name)
    return bad


def _actions(domain, runner: str, persona: str, task: str, seed: int) -> list:
    env = Env(domain, task=task, persona=persona, seed=seed)
    env.reset()
    play(runner, env)
    return [e.text for e in env.world.trace]


@pytest.mark.parametrize("runner,persona,task,seed", CASES, ids=[f"{c[0]}-{c[1]}-{c[2]}-{c[3]}" for c in CASES])
def test_every_printed_id_binds_in_the_next_action(domain, runner, persona, task, seed):
    if task not in domain.task:
        pytest.skip(f"no task {task}")
    actions = _actions(domain, runner, persona, task, seed)
    assert actions, "the agent did nothing"
    env = Env(domain, task=task, persona=persona, seed=seed)
    start = env.reset()
    assert not _unbound(env.world, start), "the layout prints ids the agent cannot name"
    printed = 0
    for text in actions:
        r = env.step(text)
        if not r.ok:
            continue  # a failure may echo the agent's own unknown name back
        printed += len(_WORD.findall(r.observation))
        bad = _unbound(env.world, r.observation)
        assert not bad, f"after {text!r}: {bad} printed in {r.observation!r} but not usable"
    assert printed > len(actions)


def test_results_and_opened_contents_bind(domain):
    """Results an action names (`to get cracked_eggs`) and what an opened fridge shows can be named next."""
    env = Env(domain, task="eggs", persona=None, full_scene=True)
    env.reset()
    for text in ["Open fridge_0", "Look for pan", "Move pan_1 to stove_0"]:
        r = env.step(text)
        assert r.ok, r.observation
        assert not _unbound(env.world, r.observation)
    eggs = sorted(e for e in env.world.known if env.world.specs[e].category == "egg")
    assert eggs, "opening the fridge shows the eggs"
    for text in [f"Move {eggs[0]} to pan_1", "crack items in pan_1 to get cracked_eggs", "Turn on stove_0",
                 "Move cracked_eggs from pan_1 to plate_0" if "plate_0" in env.world.known else "Look for plate"]:
        r = env.step(text)
        assert r.ok, f"{text}: {r.observation}"
        assert not _unbound(env.world, r.observation)
