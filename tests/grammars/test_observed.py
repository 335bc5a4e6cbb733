"""`Env.observed()`: what the agent may name, as a read-only snapshot."""

from __future__ import annotations

import random

import pytest

from adaptbench.grammars import build_index
from adaptbench.grammars.sample import sample
from adaptbench.runtime.actions import compile_templates, match
from adaptbench.runtime.env import Env


@pytest.fixture(scope="module")
def domain(small_domain):
    """Engine test: the small test spec (tests/spec_small), not the paper's."""
    return small_domain


@pytest.fixture(scope="module")
def index(domain):
    return build_index(domain)


def test_observed_starts_with_the_layout_and_grows_with_discovery(domain, index):
    env = Env(domain, "eggs", seed=None, full_scene=True)
    env.reset()
    first = env.observed()
    assert first.entities == frozenset(index.layout) and first.contents == frozenset(index.layout_contents)
    env.step("Look for eggs")
    after = env.observed()
    assert first.entities < after.entities and "egg_0" in after.entities
    assert isinstance(after.entities, frozenset) and "egg_0" not in first.entities  # a snapshot, not a view


def test_results_the_agent_made_can_be_named(domain):
    env = Env(domain, "eggs", seed=None, full_scene=True)
    env.reset()
    for a in ("Look for eggs", "Look for pan", "Move pan_0 to stove_0", "Move egg_0 to pan_0", "Turn on stove_0",
              "scramble items in pan_0 to get my_eggs"):
        assert env.step(a).ok, a
    obs = env.observed()
    assert "my_eggs" in obs.entities | obs.contents


def test_forced_question_samples_are_asks(domain, index):
    templates = compile_templates(domain)  # the regex path, kept as a test oracle
    rng = random.Random(4)
    env = Env(domain, "eggs")
    for _ in range(200):
        text, action, slots = sample(index, env.observed(), rng, actions=("ask",))
        hit = match(templates, text)
        assert action == "ask" and hit is not None and (hit[0].id, hit[1]) == (action, slots)
