"""Fixtures of the language-model tests: a view after a few steps, and the tiny model (built once per
session into a temporary directory; the model tests skip, saying why, when the `models` extra is not
installed)."""

from __future__ import annotations

import importlib.util

import pytest

MODEL_DEPS = ("torch", "transformers", "tokenizers", "llguidance")
MISSING = [m for m in MODEL_DEPS if importlib.util.find_spec(m) is None]
SKIP_MODELS = pytest.mark.skipif(bool(MISSING), reason=f"models extra not installed (missing {', '.join(MISSING)}): "
                                 "pip install torch==2.13.0 && pip install -e '.[dev,models]'")
STEPS = ("Look for eggs", 'Ask "How do you like your eggs?"', "Open fridge_0", "Move egg_0 to counter_0")


def play(domain, task="eggs", persona="juan", seed=0, steps=STEPS, agent="planner"):
    """An episode in flight after the given actions (offline user)."""
    from adaptbench.agents.users import OfflineUser
    from adaptbench.harness.batches import episode_id
    from adaptbench.harness.episode import Episode
    from adaptbench.harness.policy import Decision
    from adaptbench.harness.rollout import Job
    from adaptbench.runtime.env import Env

    env = Env(domain, task, persona, seed, user=OfflineUser(domain, domain.persona[persona], domain.task[task]))
    ep = Episode(episode_id(Job(agent, persona, task, seed)), env)
    made_after = []
    for a in steps:
        ep.apply(Decision(a))
        made_after.append(ep.view().made)
    return ep, tuple(made_after)


@pytest.fixture(scope="session")
def tiny(domain, tmp_path_factory):
    """The tiny model's directory."""
    if MISSING:
        pytest.skip(f"models extra not installed (missing {', '.join(MISSING)})")
    from adaptbench.llm.tiny import init_tiny

    return init_tiny(domain, tmp_path_factory.mktemp("tiny"))


@pytest.fixture(scope="session")
def backend(tiny):
    """The transformers backend on the tiny model (greedy, CPU)."""
    from adaptbench.llm.hf import TransformersBackend

    return TransformersBackend(str(tiny), batch_size=16)
