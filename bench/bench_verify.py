"""Evaluating all of a persona's preferences on a 50-step trace.

Compared with compiling the rules afresh for every evaluation (what a verifier without the compiled
rule cache does) and with the cost of simulating the 50-step episode itself.
"""

from __future__ import annotations

from adaptbench.compiler import load_domain
from adaptbench.runtime.env import Env
from adaptbench.runtime.tables import domain_tables

from .common import SPEC, episode_actions, report, timeit


def run(quick: bool = False) -> list:
    """Measure and return report rows."""
    domain = load_domain(SPEC)
    rows = []
    personas = domain.personas or ()
    if not personas:
        return [("evaluate persona preferences", float("nan"), "ms", "< 2 ms", "no personas in the spec")]
    env = Env(domain, task="toast_coffee", persona=personas[0].id, full_scene=True)
    env.reset()
    for a in episode_actions():
        env.step(a)
    worst, worst_persona = 0.0, personas[0]
    for p in personas:
        env.persona = p
        t = timeit(env.evaluate, repeat=3 if quick else 20, number=5)
        if t > worst:
            worst, worst_persona = t, p
    env.persona = worst_persona

    def uncompiled():
        domain_tables(domain).rules.clear()
        env.evaluate()
    slow = timeit(uncompiled, repeat=3 if quick else 10)

    def simulate():
        e = Env(domain, task="toast_coffee", persona=None, full_scene=True)
        e.reset()
        for a in episode_actions():
            e.step(a)
    sim = timeit(simulate, repeat=3 if quick else 10)
    n = max(len(p.preferences) for p in personas)
    rows.append((f"evaluate a persona, worst of {len(personas)} ({worst_persona.id}, {n} prefs max)", worst * 1e3,
                 "ms", "< 2 ms",
                 f"{slow / worst:.1f}x recompiling rules each time ({slow * 1e3:.2f} ms); "
                 f"{worst / sim:.0%} of simulating the episode ({sim * 1e3:.2f} ms)"))
    return rows


if __name__ == "__main__":
    report(run())
