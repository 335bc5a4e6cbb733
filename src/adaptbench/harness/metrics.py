"""Episode-set metrics beyond the mean satisfaction rate (`adapt eval` shows them per method).

- SUCCESS of an episode: at least one preference applied and every applicable preference was satisfied
  (p- = 0, p+ >= 1). A task component left unfinished violates the preferences about it (the paper's
  rule), so an episode that gives up on a part of the task with a preference does not succeed. Episodes
  in which no preference applied are neither successes nor failures: they are left out.
- pass^k, tau-bench's estimator: for each (method, persona, task) pair with n counted episodes (scene
  seeds) of which c succeeded, pass^k = C(c, k) / C(n, k), the chance that k episodes drawn without
  replacement all succeed; the row's pass^k is the mean over its pairs with n >= k. pass^1 is the mean
  success rate. `adapt eval` shows pass^1 and pass^K, K = the smallest n every pair of the whole table has
  (`common_k`), so rows compare; `--pass-k 1,2,4` picks others. Pairs with no counted episode are left
  out and counted.
- question precision: the share of questions (a successful `Ask`) whose answer revealed a preference
  that applies to the task and was not yet known: the question's `targets` (the preferences the
  offline user's matcher answered from, recorded since record version 2) include a preference whose
  verdict is not `inapplicable` and that no earlier question of the episode targeted. The other
  questions are counted as `repeat` (only preferences already asked about) or `off` (no applicable
  preference: chit-chat, world-state questions, preferences of other tasks). Records older than version 2
  carry no targets: their questions are not judged (n/a).
"""

from __future__ import annotations

from collections import Counter, defaultdict
from dataclasses import dataclass
from math import comb


@dataclass(frozen=True)
class PassK:
    """pass^k of one method for each k in `ks`: `rates[i]` (None where no pair has k episodes) over
    `pairs[i]` pairs; `left_out`: pairs with no episode in which a preference applied."""

    ks: tuple
    rates: tuple
    pairs: tuple
    left_out: int

    def rate(self, k: int):
        """pass^k, or None (no pair has k counted episodes, or k was not computed)."""
        return self.rates[self.ks.index(k)] if k in self.ks else None


@dataclass(frozen=True)
class Precision:
    """Question precision of one method: questions that revealed a new applicable preference, questions
    judged, those that only repeated known preferences, those with no applicable preference, and
    questions in records without targets (older than version 2, not judged)."""

    precise: int
    judged: int
    unjudged: int
    repeat: int = 0
    off: int = 0

    @property
    def rate(self):
        """precise / judged, or None when nothing was judged (n/a)."""
        return self.precise / self.judged if self.judged else None


def fully_satisfied(record) -> bool:
    """Whether every applicable preference was satisfied in the episode (it had at least one)."""
    return record.satisfaction_rate is not None and not record.violated and record.satisfaction_rate == 1


def outcomes(records: list) -> dict:
    """(persona, task) -> (n, c): counted episodes (some preference applied) and successes; pairs with no
    counted episode map to (0, 0)."""
    out = {}
    for r in records:
        n, c = out.get((r.persona, r.task), (0, 0))
        counted = r.satisfaction_rate is not None
        out[(r.persona, r.task)] = (n + counted, c + (counted and fully_satisfied(r)))
    return out


def common_k(records: list) -> int | None:
    """The smallest number of counted episodes every (method, persona, task) pair of `records` has (pairs
    with none left out; None when there is no counted episode): the largest k every row can be judged on."""
    per = defaultdict(int)
    for r in records:
        if r.satisfaction_rate is not None:
            per[(r.agent, r.persona, r.task)] += 1
    return min(per.values(), default=None)


def pass_hat_k(n: int, c: int, k: int) -> float:
    """C(c, k) / C(n, k): the chance that k of the n episodes, drawn without replacement, all succeed."""
    return comb(c, k) / comb(n, k)


def pass_k(records: list, ks=(1,)) -> PassK:
    """pass^k of one method's episode records for each k in `ks` (see the module doc)."""
    pairs = outcomes(records)
    counted = [(n, c) for n, c in pairs.values() if n]
    rates, used = [], []
    for k in ks:
        values = [pass_hat_k(n, c, k) for n, c in counted if n >= k]
        rates.append(sum(values) / len(values) if values else None)
        used.append(len(values))
    return PassK(tuple(ks), tuple(rates), tuple(used), len(pairs) - len(counted))


def applicable(record) -> set:
    """The ids of the preferences that applied in an episode."""
    return {p.get("id") for p in record.preferences if p.get("verdict") != "inapplicable"}


def judge_questions(record) -> list:
    """'precise', 'repeat', 'off' or None (no targets recorded) for each question of the episode, in order."""
    ids, known, out = applicable(record), set(), []
    for step in (s for s in record.steps if s.is_question):
        if step.targets is None:
            out.append(None)
            continue
        hit = ids & set(step.targets)
        out.append("precise" if hit - known else "repeat" if hit else "off")
        known |= hit
    return out


def precision(records: list) -> Precision:
    """Question precision of one method's episode records (see the module doc)."""
    counts = Counter(v for r in records for v in judge_questions(r))
    judged = counts["precise"] + counts["repeat"] + counts["off"]
    return Precision(counts["precise"], judged, counts[None], counts["repeat"], counts["off"])
