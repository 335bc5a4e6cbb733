"""Auditing the LLM persona user like the offline one (`qa.fidelity`): for every preference, probe
questions a planner would ask; an answer names the preference when it shares a content word with the
preference's topics; the same question in the same state must get the same answer; location probes
must not be answered with where things are (an entity id or a furniture word of the house)."""

from __future__ import annotations

import re
from dataclasses import dataclass

from ..agents.users import words
from ..compiler.lint import applies_to
from ..qa.fidelity import LOCATION_PROBES, probes
from ..runtime.env import Env
from .user import LLMUser


@dataclass(frozen=True)
class Probe:
    """One probe of the LLM user and what came back."""

    persona: str
    preference: str
    question: str
    answer: str
    hit: bool
    consistent: bool


def names(pref, answer: str) -> bool:
    """Whether an answer names a preference: a content word shared with its topics (or, when it has
    no topics, its text)."""
    topic = set().union(*(words(t) for t in pref.topics)) if pref.topics else words(pref.text)
    return bool(words(answer) & topic)


def leaks(env: Env, answer: str) -> bool:
    """Whether an answer tells where things are: an entity id of the scene, or a word of a furniture
    id (`fridge`, `cabinet`, `drawer`, ...)."""
    toks = set(re.findall(r"[a-z][a-z0-9_]*", answer.lower()))
    if toks & set(env.world.specs):
        return True
    furniture = {w for e, s in env.world.specs.items() if s.kind == "furniture"
                 for w in re.findall(r"[a-z]+", e) if len(w) > 3}
    return bool(toks & furniture)


def audit(domain, backend, personas=None, max_probes: int | None = None) -> tuple:
    """Probe the LLM user; returns (probes, summary) with hit rate, consistency and location leaks."""
    out, leaked = [], 0
    for persona in (domain.persona[p] for p in (personas or list(domain.persona))):
        for pref in persona.preferences:
            tasks = [t for t in domain.tasks if applies_to(domain, pref, t)] or list(domain.tasks)
            env = Env(domain, tasks[0].id, persona.id, 0)
            user = LLMUser(backend, domain, persona, tasks[0]).bind(env)
            for q in probes(pref)[:max_probes]:
                a = user.answer(q)
                out.append(Probe(persona.id, pref.id, q, a, names(pref, a), user.answer(q) == a))
        env = Env(domain, domain.tasks[0].id, persona.id, 0)
        user = LLMUser(backend, domain, persona, domain.tasks[0]).bind(env)
        leaked += sum(leaks(env, user.answer(q)) for q in LOCATION_PROBES)
    hits = sum(p.hit for p in out)
    return out, {"probes": len(out), "hits": hits, "hit_rate": hits / len(out) if out else 0.0,
                 "consistent": all(p.consistent for p in out), "location_leaks": leaked}
