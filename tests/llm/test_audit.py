"""The LLM user's audit: naming a preference and leaking locations (no model needed)."""

from __future__ import annotations

import pytest

from adaptbench.llm.audit import leaks, names
from adaptbench.runtime.env import Env


def test_an_answer_names_a_preference_by_its_topics(domain):
    pref = {p.id: p for p in domain.persona["juan"].preferences}["whole_milk_in_eggs"]
    assert names(pref, "Please put some milk in my eggs.", "How do you like your eggs?")
    assert not names(pref, "I'm flexible, you choose.")


def test_location_leaks(domain):
    env = Env(domain, "eggs", "juan", 0)
    assert leaks(env, "The milk is in the fridge.")
    assert leaks(env, "Try cabinet_2.")
    assert not leaks(env, "I don't know where it is; please search the house. I like whole milk.")
    q = "Which cabinet has the mugs?"  # an echo names the question's furniture word and tells nothing
    assert not leaks(env, f"The robot asks: {q}", q)
    assert leaks(env, "The mugs are in cabinet_2.", q) and leaks(env, "Look in the fridge.", q)


def test_users_check_llm_needs_a_model(capsys):
    from adaptbench.cli import main

    assert main(["users", "check", "--llm"]) == 2
    assert "--user-model" in capsys.readouterr().err


class _Scripted:
    """A backend whose user answers by a rule from the question in the prompt (no model)."""

    name = "scripted"

    def __init__(self, tokenizer, rule):
        self.tokenizer, self.rule = tokenizer, rule

    def generate(self, requests):
        from adaptbench.llm.backend import Completion

        out = []
        for r in requests:
            question = r.prompt.rsplit("The robot asks: ", 1)[1].split("<|end|>")[0].strip()
            out.append(Completion(self.rule(question), 10, 5, True))
        return out

    def config(self):
        return {"backend": self.name}

    def release(self, session):
        pass


def _tokenizer(domain):
    pytest.importorskip("transformers", reason="the audit renders prompts with a tokenizer (models extra)")
    from adaptbench.llm.tiny import train_tokenizer

    return train_tokenizer(domain, 512)


def test_a_user_that_echoes_every_question_scores_zero(domain):
    """The audit counted the question's own words: an echo scored 100% (the SmolLM2 user did this)."""
    from adaptbench.llm.audit import audit

    echo = _Scripted(_tokenizer(domain), lambda q: f"The robot asks: {q}")
    probes, s = audit(domain, echo, ["juan", "maya"], progress=None)
    assert s["probes"] > 10 and s["hits"] == 0 and s["hit_rate"] == 0.0
    assert s["echo"] == s["probes"] and all(p.verdict == "echo" for p in probes)


def test_non_answers_miss_and_the_offline_answers_hit(domain):
    from adaptbench.agents.users import OfflineUser
    from adaptbench.llm.audit import audit

    tok = _tokenizer(domain)
    _, s = audit(domain, _Scripted(tok, lambda q: "I don't mind, you choose."), ["juan"], progress=None)
    assert s["hits"] == 0 and s["non-answer"] == s["probes"]
    juan = OfflineUser(domain, domain.persona["juan"])
    probes, s = audit(domain, _Scripted(tok, juan.answer), ["juan"], progress=None)
    assert s["hit_rate"] >= 0.9 and s["location_leaks"] == 0, [p for p in probes if not p.hit]


def test_verdicts_count_only_words_the_question_did_not_contain(domain):
    from adaptbench.llm.audit import verdict

    pref = {p.id: p for p in domain.persona["juan"].preferences}["whole_milk_in_eggs"]
    q = "How do you like your eggs?"
    assert verdict(pref, q, "I like my eggs.") == "echo"
    assert verdict(pref, q, "Scrambled, with a splash of whole milk.") == "hit"
    assert verdict(pref, q, "I'm flexible about eggs.") == "non-answer"
    assert verdict(pref, q, "Sunny weather today.") == "miss"


class _Counting(_Scripted):
    """A scripted backend that records how many requests each `generate` call carried."""

    def __init__(self, tokenizer, rule):
        super().__init__(tokenizer, rule)
        self.sizes: list = []

    def generate(self, requests):
        self.sizes.append(len(requests))
        return super().generate(requests)


def test_answers_are_generated_in_batches(domain):
    """The audit asks `batch` users at a time (one generate call each), not one by one."""
    from adaptbench.agents.users import OfflineUser
    from adaptbench.llm.audit import audit
    from adaptbench.qa.fidelity import LOCATION_PROBES

    juan = OfflineUser(domain, domain.persona["juan"])
    backend = _Counting(_tokenizer(domain), juan.answer)
    probes, s = audit(domain, backend, ["juan"], progress=None, batch=5)
    assert max(backend.sizes) == 5 and sum(backend.sizes) == 2 * len(probes) + len(LOCATION_PROBES)  # twice each
    assert s["consistent"]


def test_an_answer_that_changes_when_asked_again_is_inconsistent(domain):
    from adaptbench.llm.audit import audit

    calls = iter(range(10 ** 6))
    _, s = audit(domain, _Scripted(_tokenizer(domain), lambda q: f"whole milk {next(calls)}"), ["juan"],
                 progress=None)
    assert not s["consistent"] and s["inconsistent"] == s["probes"]
