"""Fixtures of the environment tests: oracle episodes played in-process (actions and verdicts)."""

from __future__ import annotations

import pytest


def oracle_episode(domain, task: str, persona: str, seed: int) -> dict:
    """The oracle's actions on an episode and the verdicts they earn, run in-process."""
    from adaptbench.agents.scripted import play
    from adaptbench.envs.session import Session

    s = Session.open(domain, task, persona, seed)
    ep = play("oracle", s.env)
    return {"task": task, "persona": persona, "seed": seed, "actions": [st.action for st in ep.steps],
            "verdicts": s.env.evaluate().as_dict()}


@pytest.fixture(scope="session")
def oracle_eggs(domain):
    """juan makes eggs on seed 0, played by the oracle."""
    return oracle_episode(domain, "eggs", "juan", 0)


@pytest.fixture(scope="session")
def oracle_mix(domain):
    """8 distinct oracle episodes (tasks x personas x seeds)."""
    combos = [("eggs", "juan", 0), ("toast_coffee", "ron", 1), ("cereal_coffee", "sarah", 2), ("tea_eggs", "lisa", 3),
              ("parfait", "maya", 0), ("omelette", "carlos", 1), ("tea_toast", "ethan", 2), ("cereal", "rachel", 3)]
    return [oracle_episode(domain, *c) for c in combos]


@pytest.fixture(scope="session")
def tiny(domain, tmp_path_factory):
    """The tiny model's directory (built once, as tests/llm does)."""
    pytest.importorskip("tokenizers", reason="models extra not installed")
    pytest.importorskip("torch", reason="models extra not installed")
    from adaptbench.llm.tiny import init_tiny

    return init_tiny(domain, tmp_path_factory.mktemp("tiny"))
