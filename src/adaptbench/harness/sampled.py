"""How `adapt eval` treats sampled runs and prompts over budget (record version 3, `record.py`).

    records = by_temperature(records)        # an agent run at several temperatures: one row per temperature
    for line in sampling_notes(records): print(line)

- Sample seeds are averaged: episodes of one agent at one temperature under several sample seeds are
  independent samples of the same policy, so they count together in the agent's row (means and standard
  errors over all of them) and in pass^k (a pair passes only if every sample of its first k scene seeds
  passes); a note says how many seeds each row holds.
- Temperatures are kept apart: an agent with episodes at several temperatures gets one row per
  temperature (`planner (T=1)`), since those are different policies.
- Prompts over budget are counted: steps whose prompt exceeded `--budget` even with every older step left
  out (`over_budget` in the step's stats), and the model records too old (before version 3) to say.
"""

from __future__ import annotations

import dataclasses
from collections import defaultdict

OVER_BUDGET_VERSION = 3


def by_temperature(records: list) -> list:
    """The records, an agent with episodes at several temperatures renamed per temperature
    (`planner (T=1)`); others unchanged."""
    temps = defaultdict(set)
    for r in records:
        temps[r.agent].add(r.temperature)
    mixed = {a for a, ts in temps.items() if len(ts) > 1}
    return [dataclasses.replace(r, agent=f"{r.agent} (T={_t(r.temperature)})") if r.agent in mixed else r
            for r in records]


def _t(temperature) -> str:
    return "?" if temperature is None else f"{temperature:g}"


def seed_notes(records: list) -> list:
    """One line per agent whose episodes were sampled under more than one sample seed."""
    seeds = defaultdict(set)
    for r in records:
        if r.sample_seed is not None:
            seeds[(r.agent, r.temperature)].add(r.sample_seed)
    out = []
    for (agent, t), ss in sorted(seeds.items(), key=lambda x: x[0][0]):
        if len(ss) > 1:
            n = sum(1 for r in records if r.agent == agent)
            out.append(f"{agent}: {n} episodes sampled at temperature {_t(t)} under {len(ss)} sample seeds "
                       f"({', '.join(map(str, sorted(ss)))}), averaged as independent samples; pass^k requires "
                       "every sample of a pair's scene seeds to pass")
    return out


def budget_notes(records: list) -> list:
    """How many model steps had a prompt over the token budget, and how many model records cannot say."""
    model = [r for r in records if r.temperature is not None]
    over = [r for r in model if r.over_budget]
    old = sum(1 for r in model if r.version < OVER_BUDGET_VERSION)
    out = []
    if model:
        steps = sum(r.over_budget for r in over)
        out.append(f"prompts over the token budget (with every older step left out): {steps} step(s) in "
                   f"{len(over)} of {len(model)} model episode(s)")
    if old:
        out.append(f"{old} model record(s) predate version {OVER_BUDGET_VERSION} and do not record prompts over "
                   "the budget")
    return out


def sampling_notes(records: list) -> list:
    """The lines `adapt eval` prints under its table about sample seeds and prompts over budget."""
    return seed_notes(records) + budget_notes(records)
