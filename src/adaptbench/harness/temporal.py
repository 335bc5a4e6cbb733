"""Preference satisfaction over the course of an interaction: the paper's temporal figure (Appendix,
"Preference elicitation performance over time").

The verifiers are meant for a finished trajectory (a preference such as "no sugar" or "tea before
toast" can look satisfied on a partial one), so, as the paper does, at each step only the preferences
that are SATISFIED AT THE END are evaluated:

    curve(t) = #{p satisfied at the end and already satisfied after step t} / (p+ + p-)

with p+ and p- the final counts of the episode. curve(T) is the episode's satisfaction rate, so the
averaged curve ends at the Table 1 figure; `normalised` divides by p+ instead (the fraction of the final
score reached by step t, 1 at the end; episodes with p+ = 0 have no normalised curve).

Records keep the actions, not the world after each step, so the curve is computed by replaying the
recorded actions through the simulator (as `adapt replay` does) in the recorded scene, with the recorded
replies as the user's answers, and evaluating those preferences after every step that succeeded (a
failed action changes nothing). A replay is checked against the record: the same scene id, every step
succeeding or failing as recorded, and the same final satisfied set; an episode that does not replay
faithfully (another spec, a changed simulator) is left out and counted, never drawn.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

GRID = tuple(i / 50 for i in range(51))  # 0%, 2%, ..., 100% of the interaction


@dataclass(frozen=True)
class Curve:
    """One episode's curve: `counts[t]` = end-satisfied preferences already satisfied after step t
    (t = 0 before any step), `satisfied` = p+ and `applicable` = p+ + p- at the end."""

    counts: tuple
    satisfied: int
    applicable: int

    def at(self, x: float, normalised: bool = False) -> float | None:
        """The curve at fraction `x` of the interaction (a step function: the steps completed by then,
        floor(x * T)); None where it is undefined (nothing applicable, or p+ = 0 when normalised)."""
        denominator = self.satisfied if normalised else self.applicable
        if not denominator:
            return None
        steps = len(self.counts) - 1
        return self.counts[int(x * steps + 1e-9)] / denominator


@dataclass
class Replays:
    """Curves by method and the episodes left out, by reason."""

    curves: dict = field(default_factory=dict)  # method -> [Curve]
    skipped: Counter = field(default_factory=Counter)

    def skipped_text(self) -> str:
        """'3 episode(s) not replayed: 2 spec differs from --spec, 1 replay differs from the record' or ''."""
        if not self.skipped:
            return ""
        parts = ", ".join(f"{n} {why}" for why, n in self.skipped.most_common())
        return f"{sum(self.skipped.values())} episode(s) left out of the temporal figure: {parts}"


class _Replies:
    """The user of a replay: answers each question with the reply the record holds."""

    def __init__(self, replies: list):
        self.replies = list(replies)

    def __call__(self, question, dialogue) -> str:
        return self.replies.pop(0) if self.replies else ""


class ReplayMismatch(Exception):
    """The replay did not reproduce the record (the message says how)."""


def _final_satisfied(record) -> list:
    return [p["id"] for p in record.preferences if p.get("verdict") == "satisfied"]


def _env(record, domain):
    """The record's environment: its seed's scene, or the full scene when that is what the record's scene id
    names (`adapt play --full-scene`); the recorded replies answer its questions."""
    from ..runtime.env import Env

    replies = [s.reply for s in record.steps if s.is_question]
    for full in (False, True):
        env = Env(domain, record.task, record.persona, None if full else record.seed, full_scene=full,
                  user=_Replies(replies), max_steps=max(len(record.steps), 1))
        if record.scene is None or env.scene.scene_id == record.scene:
            return env
    raise ReplayMismatch("scene differs from the record")


def replay_curve(record, domain) -> Curve:
    """The curve of one episode record (see the module doc); ReplayMismatch when the replay does not
    reproduce the record."""
    from ..runtime.verify import Ctx, verdict

    if record.spec_hash is not None and record.spec_hash != domain.spec_hash:
        raise ReplayMismatch("spec differs from --spec")
    env = _env(record, domain)
    ids = set(_final_satisfied(record))
    prefs = [p for p in domain.persona[record.persona].preferences if p.id in ids]
    if len(prefs) != len(ids):
        raise ReplayMismatch("preferences differ from the record")

    def count() -> int:
        ctx = Ctx(domain, env.world, env.task)
        return sum(verdict(ctx, p).verdict == "satisfied" for p in prefs)

    counts = [count() if prefs else 0]
    for step in record.steps:
        result = env.step(step.action)
        if result.ok != step.ok:
            raise ReplayMismatch("replay differs from the record")
        counts.append(count() if result.ok and prefs else counts[-1])
    if counts[-1] != len(prefs):
        raise ReplayMismatch("replay differs from the record")
    applicable = (record.satisfied or 0) + (record.violated or 0)
    if record.satisfied is None or record.violated is None:
        applicable = sum(p.get("verdict") != "inapplicable" for p in record.preferences)
    return Curve(tuple(counts), len(prefs), applicable)


def replay_all(records: list, domain) -> Replays:
    """Curves of every record with an applicable preference, grouped by `record.agent` (the method label
    after `methods.resolve`); episodes with nothing applicable have no curve and are not counted."""
    out = Replays()
    for r in records:
        if r.satisfaction_rate is None:
            continue
        try:
            curve = replay_curve(r, domain)
        except ReplayMismatch as exc:
            out.skipped[str(exc)] += 1
            continue
        out.curves.setdefault(r.agent, []).append(curve)
    return out


def mean_curve(curves: list, normalised: bool = False, grid: tuple = GRID) -> list:
    """(x, mean, standard error, episodes) at each grid point over the curves defined there."""
    from .evaluate import mean_se

    out = []
    for x in grid:
        values = [v for v in (c.at(x, normalised) for c in curves) if v is not None]
        m, se = mean_se(values)
        out.append((x, m, se, len(values)))
    return out
