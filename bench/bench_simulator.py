"""Simulator throughput on a replayed 50-step episode (parse, bind, preconditions, effects).

Compared with parsing each action with a Lark LALR grammar over the same templates (what a
grammar-first simulator would do) before executing it.
"""

from __future__ import annotations

from adaptbench.compiler import load_domain
from adaptbench.runtime.env import Env

from .common import SPEC, episode_actions, report, timeit


def _lark_parser(domain):
    from lark import Lark

    rules, terms = [], []
    for i, a in enumerate(domain.actions):
        for j, form in enumerate(a.forms):
            parts = []
            for tok in form.replace("{", " {").replace("}", "} ").split():
                parts.append("WORD" if tok.startswith("{") and tok != "{question}" else
                             "QUESTION" if tok == "{question}" else f'"{tok}"i')
            rules.append(f"a{i}_{j}: " + " ".join(parts))
            terms.append(f"a{i}_{j}")
    grammar = "start: " + " | ".join(terms) + "\n" + "\n".join(rules) + """
WORD: /[^\\s"]+/
QUESTION: /"[^"]*"/
%ignore " "
"""
    return Lark(grammar, parser="earley")


def run(quick: bool = False) -> list:
    """Measure and return report rows."""
    domain = load_domain(SPEC)
    actions = episode_actions()

    def episode():
        env = Env(domain, task="toast_coffee", persona=None, full_scene=True)
        env.reset()
        for a in actions:
            env.step(a)
    reps = 3 if quick else 10
    per_episode = timeit(episode, repeat=reps)
    steps_per_s = len(actions) / per_episode
    parser = _lark_parser(domain)
    lark_parse = timeit(lambda: [parser.parse(a) for a in actions], repeat=reps) / len(actions)
    return [("simulator steps/s (50-step replay, new Env each)", steps_per_s, "steps/s", ">= 10000",
             f"a lark parse alone costs {lark_parse * 1e6:.0f} us/action = {lark_parse * steps_per_s:.1f}x our whole step")]


if __name__ == "__main__":
    report(run())
