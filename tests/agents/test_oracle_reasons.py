"""The oracle names the preferences its next action serves (issue 27 item 5): the choice of item, style or
place an action realises was decided by a preference when the plan without it treats that preference
worse; a plain step serves none. And the teacher relabels from the agent's state: what is left of its plan."""

from __future__ import annotations

import re

from adaptbench.agents.users import OfflineUser
from adaptbench.compiler.model import Persona, Preference
from adaptbench.compiler.rules import parse_rule
from adaptbench.harness.episode import Episode
from adaptbench.harness.policy import Decision
from adaptbench.runtime.env import Env


def _zed():
    prefs = (
        Preference("oat", "Oat milk in coffee", parse_rule("for coffee: it has oat_milk"), ("coffee", "milk"),
                   "I take my coffee with oat milk."),
        Preference("patio", "Zed likes breakfast served on the patio", parse_rule("for all: it served at patio"),
                   ("where", "eat", "breakfast"), "On the patio, please."),
    )
    return Persona("zed", "Zed", 99, "", prefs)


def _teacher_along_the_oracle(domain, persona, task="toast_coffee", seed=0):
    """(oracle action, teacher proposal) at every step of the oracle's own episode."""
    from adaptbench.agents.scripted import OraclePolicy
    from adaptbench.training.relabel import ScriptedTeacher

    env = Env(domain, task=task, persona=persona, seed=seed, user=OfflineUser(domain, persona, domain.task[task]))
    ep = Episode("e", env)
    teacher, oracle = ScriptedTeacher(domain), OraclePolicy(domain)
    teacher.start("e", env)
    oracle.start("e", env)
    out = []
    while not ep.done:
        view = ep.view()
        action = oracle.act(view).action
        out.append((action, teacher.proposal(view)))
        ep.apply(Decision(action))
    return out, env.evaluate()


def test_oracle_actions_name_the_preference_that_decided_their_choice(domain):
    steps, ev = _teacher_along_the_oracle(domain, _zed())
    assert ev.satisfied == 2
    named = {a: p.preferences for a, p in steps}
    oat = [a for a in named if "oat_milk" in a]
    assert oat and all(named[a] == ("oat",) for a in oat)  # the milk is oat milk because of "oat"
    served = [a for a in named if re.fullmatch(r"Move (plate|mug)_\d+ to \w+", a)]
    assert len(served) == 2 and all(domain.entity[a.split()[-1]].location == "patio" for a in served)
    assert all(named[a] == ("patio",) for a in served)  # the place it is served at: "patio"
    plain = [a for a in named if a.startswith(("Turn on", "Look for bread"))]
    assert plain and all(named[a] == () for a in plain)  # cooking steps serve no preference


def test_reason_is_the_paper_s_thought(domain):
    steps, _ = _teacher_along_the_oracle(domain, _zed())
    p = next(p for a, p in steps if "oat_milk" in a and a.startswith("Pour"))
    assert p.reason == f'Since Zed prefers this: "Oat milk in coffee", my next step is {p.action}.'
    q = next(p for a, p in steps if p.preferences == ("patio",))
    assert q.reason.startswith("Since Zed likes breakfast served on the patio, my next step is Move ")
    assert all(p.reason is None for _, p in steps if not p.preferences)


def test_teacher_relabels_from_the_agent_s_state_not_the_plan_s_start(domain):
    """Before: the teacher re-ran its plan from the first step, so after the agent had moved the pan it
    proposed `Move pan_0 to stove_0` for the rest of the episode."""
    steps, _ = _teacher_along_the_oracle(domain, domain.persona["ron"], task="eggs", seed=100)
    same = [re.sub(r"_\d+", "", a) == re.sub(r"_\d+", "", p.action) for a, p in steps]
    assert all(same), [(a, p.action) for a, p in steps]
    assert len({p.action for _, p in steps}) > len(steps) // 2


def test_since_reads_the_preference_texts():
    from adaptbench.training.relabel import since

    assert since("Ron", "He prefers his coffee to be served first") == "Ron prefers his coffee to be served first"
    assert since("Ron", "Ron likes vegetables with eggs.") == "Ron likes vegetables with eggs"
    assert since("Sarah", "Prefer oat milk") == "Sarah prefers oat milk"
    assert since("Sarah", "Add cheese to eggs") == 'Sarah prefers this: "Add cheese to eggs"'


def test_an_action_that_serves_a_preference_names_oracle_ask_s_question(domain):
    """`questions`: the choice point's question (the words `oracle-ask` asks it in) for an action whose choice
    a preference decided; none for a plain step."""
    steps, _ = _teacher_along_the_oracle(domain, _zed())
    oat = next(p for a, p in steps if "oat_milk" in a)
    patio = next(p for a, p in steps if p.preferences == ("patio",))
    asks = {c.ask for c in domain.planning} | {c.ask for r in domain.recipes for c in r.choices}
    assert oat.questions and set(oat.questions) <= asks and "milk" in oat.questions[0].lower()
    assert patio.questions and set(patio.questions) <= asks
    assert all(p.questions == () for _, p in steps if not p.preferences)
    oracle_ask = _oracle_ask_questions(domain, _zed())
    assert oat.questions[0] in oracle_ask and patio.questions[0] in oracle_ask


def _oracle_ask_questions(domain, persona, task="toast_coffee", seed=0) -> set:
    from adaptbench.agents.scripted import play
    from adaptbench.training.relabel import question_text

    env = Env(domain, task=task, persona=persona, seed=seed, user=OfflineUser(domain, persona, domain.task[task]))
    return {question_text(t.action) for t in play("oracle-ask", env).view().history if t.action.startswith("Ask")}
