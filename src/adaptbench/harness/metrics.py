"""Episode-set metrics beyond the mean satisfaction rate (`adapt eval` shows them per agent).

- pass^k over scene seeds: the share of (agent, persona, task) pairs whose episodes are fully
  satisfied (every applicable preference satisfied, none violated) in all k seeds; `adapt eval` uses ONE k
  for every row, the smallest number of seeds every (agent, persona, task) pair has (`common_k`), each
  pair counting its first k seeds (lowest seed numbers), and says which k under the table. Pairs in which no
  preference applied in any episode are left out and counted; episodes with no applicable
  preference inside a counted pair are ignored.
- question precision: the share of questions whose answer named a preference that applies to the
  task (a question step's `targets` meets the record's preferences with a verdict other than
  `inapplicable`). Records written before version 2 carry no targets: n/a.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass


@dataclass(frozen=True)
class PassK:
    """pass^k of one agent: pairs passing in every seed, pairs counted, the seeds per pair (min, max)
    and the pairs left out (no applicable preference)."""

    passed: int
    pairs: int
    k: tuple
    left_out: int

    @property
    def rate(self):
        """passed / pairs, or None when no pair counts."""
        return self.passed / self.pairs if self.pairs else None

    @property
    def k_text(self) -> str:
        """'3', or '2-3' when pairs have different numbers of seeds; '' when there are none."""
        if not self.k:
            return ""
        lo, hi = self.k
        return str(lo) if lo == hi else f"{lo}-{hi}"


@dataclass(frozen=True)
class Precision:
    """Question precision of one agent: questions naming an applicable preference, questions judged,
    and questions in records without targets (older than version 2, not judged)."""

    precise: int
    judged: int
    unjudged: int

    @property
    def rate(self):
        """precise / judged, or None when nothing was judged (n/a)."""
        return self.precise / self.judged if self.judged else None


def fully_satisfied(record) -> bool:
    """Whether every applicable preference was satisfied in the episode (it had at least one)."""
    return record.satisfaction_rate is not None and not record.violated and record.satisfaction_rate == 1


def common_k(records: list) -> int | None:
    """The smallest number of seeds every (agent, persona, task) pair of `records` has (None for no records):
    the one k of pass^k for a whole table, so its rows compare."""
    seeds = defaultdict(set)
    for r in records:
        seeds[(r.agent, r.persona, r.task)].add(r.seed)
    return min((len(s) for s in seeds.values()), default=None)


def pass_k(records: list, k: int | None = None) -> PassK:
    """pass^k of one agent's episode records (see the module docstring); with `k`, each pair counts only its
    first k seeds (the lowest), so every pair and every agent is judged on the same number of seeds."""
    pairs = defaultdict(list)
    for r in records:
        pairs[(r.persona, r.task)].append(r)
    if k is not None:
        for key, recs in pairs.items():
            keep = set(sorted({r.seed for r in recs}, key=lambda s: (s is None, s))[:k])
            pairs[key] = [r for r in recs if r.seed in keep]
    counted = {key: [r for r in recs if r.satisfaction_rate is not None] for key, recs in pairs.items()}
    counted = {key: recs for key, recs in counted.items() if recs}
    seeds = [len({r.seed for r in pairs[key]}) for key in counted]
    passed = sum(1 for recs in counted.values() if all(fully_satisfied(r) for r in recs))
    return PassK(passed, len(counted), (min(seeds), max(seeds)) if seeds else (), len(pairs) - len(counted))


def applicable(record) -> set:
    """The ids of the preferences that applied in an episode."""
    return {p.get("id") for p in record.preferences if p.get("verdict") != "inapplicable"}


def precision(records: list) -> Precision:
    """Question precision of one agent's episode records (see the module docstring)."""
    precise = judged = unjudged = 0
    for r in records:
        ids = applicable(r)
        for step in (s for s in r.steps if s.is_question):
            if step.targets is None:
                unjudged += 1
                continue
            judged += 1
            precise += bool(ids & set(step.targets))
    return Precision(precise, judged, unjudged)
