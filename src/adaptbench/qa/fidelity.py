"""How faithful the offline user is: for every preference, probe questions a planner would ask must
be answered with that preference; the same question gets the same answer; locations are never revealed."""

from __future__ import annotations

from dataclasses import dataclass

from ..agents.users import NO_LOCATION, OfflineUser
from ..compiler.lint import applies_to
from ..compiler.model import CompiledDomain, Preference

LOCATION_PROBES = ("Where is the milk?", "Where can I find the eggs?", "Which cabinet has the mugs?")


def probes(pref: Preference) -> list:
    """Questions a planner would ask about this preference, built from its topics."""
    t = list(pref.topics)
    out = [f"How do you like your {t[0]}?", f"Do you have any preference about {' or '.join(t[:2])}?"]
    if len(t) > 2:
        out.append(f"What about {t[2]} with your breakfast?")
    return out


@dataclass(frozen=True)
class ProbeResult:
    """One probe and whether the answer carried the preference."""

    persona: str
    preference: str
    question: str
    hit: bool
    answer: str


def check(domain: CompiledDomain) -> tuple[list, dict]:
    """Run every probe for every persona over every task it applies to; return results and summary."""
    results = []
    consistent, leaks = True, 0
    for persona in domain.personas:
        for pref in persona.preferences:
            tasks = [t for t in domain.tasks if applies_to(domain, pref, t)] or [None]
            user = OfflineUser(domain, persona, tasks[0])
            for q in probes(pref):
                answer = user.answer(q)
                hit = pref in user.pick(q)
                consistent &= user.answer(q) == answer
                results.append(ProbeResult(persona.id, pref.id, q, hit, answer))
        user = OfflineUser(domain, persona)
        leaks += sum(user.answer(q) != NO_LOCATION for q in LOCATION_PROBES)
    hits = sum(r.hit for r in results)
    summary = {"probes": len(results), "hits": hits, "hit_rate": hits / len(results) if results else 0.0,
               "consistent": consistent, "location_leaks": leaks}
    return results, summary
