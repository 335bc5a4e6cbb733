"""The LLM user's audit: naming a preference and leaking locations (no model needed)."""

from __future__ import annotations

from adaptbench.llm.audit import leaks, names
from adaptbench.runtime.env import Env


def test_an_answer_names_a_preference_by_its_topics(domain):
    pref = {p.id: p for p in domain.persona["juan"].preferences}["whole_milk_in_eggs"]
    assert names(pref, "Please put some milk in my eggs.")
    assert not names(pref, "I'm flexible, you choose.")


def test_location_leaks(domain):
    env = Env(domain, "eggs", "juan", 0)
    assert leaks(env, "The milk is in the fridge.")
    assert leaks(env, "Try cabinet_2.")
    assert not leaks(env, "I don't know where it is; please search the house. I like whole milk.")


def test_users_check_llm_needs_a_model(capsys):
    from adaptbench.cli import main

    assert main(["users", "check", "--llm"]) == 2
    assert "--user-model" in capsys.readouterr().err
