"""Paired comparison (`adapt eval --paired METHOD`): every other method's satisfaction minus METHOD's on the
very same episodes — the same split, persona, task and scene seed — for seen and unseen personas.

Two methods evaluated on the same episodes share each episode's difficulty (a hard persona, a scene with the
milk out of reach), so the standard error of the per-episode difference is much smaller than the two rows'
standard errors combined: this is the comparison to use when asking whether a trained model beats its base.
An episode counts when both methods have a satisfaction rate for it (an episode with no applicable
preference has none); a record without a split (an untrained agent) pairs with the other side's record of any split
when there is only one; several sample seeds of one episode count as their mean.

The standard error is clustered by scene (split, task and scene seed): the personas evaluated in one scene share
its difficulty, and a model that never asks does exactly the same in it for all of them (measured: the shipped
student's actions were identical for the 4 unseen personas in all 32 scenes of split 0's evaluation), so they are
not independent draws. On split 0's 128 unseen episodes (4 personas x 32 scenes), a continued student against
the base: -4.9 points, ± 1.9 per episode, ± 3.1 clustered. With one episode a scene it is the plain standard
error of the mean. A difference is called
clear when it is larger than twice its standard error, over at least two scenes."""

from __future__ import annotations

import math
from dataclasses import dataclass

from .evaluate import fixed_width, markdown, split_of


@dataclass(frozen=True)
class PairedRow:
    """One method against the reference in one column: episodes paired, mean difference and its standard
    error clustered by scene (satisfaction rate, 0-1), how many episodes it did better, worse or the same on,
    and the scenes the episodes fall in."""

    method: str
    column: str  # "seen" or "unseen"
    n: int
    mean: float
    se: float
    better: int
    worse: int
    same: int
    scenes: int

    @property
    def clear(self) -> bool:
        """Whether the difference is larger than twice its standard error (two scenes at least)."""
        return self.scenes > 1 and abs(self.mean) > 2 * self.se


def clustered_mean_se(clusters: dict) -> tuple:
    """Mean of every value in `clusters` ({cluster: [values]}) and its cluster-robust standard error:
    sqrt(C / (C - 1) * sum over clusters of (sum of (value - mean))^2) / n, for C clusters and n values
    (with one value a cluster, the plain standard error of the mean); 0 with fewer than two clusters."""
    values = [v for vs in clusters.values() for v in vs]
    n, c = len(values), len(clusters)
    m = sum(values) / n
    if c < 2:
        return m, 0.0
    spread = sum(sum(v - m for v in vs) ** 2 for vs in clusters.values())
    return m, math.sqrt(spread * c / (c - 1)) / n


def _key(record) -> tuple:
    return (record.split, record.persona, record.task, record.seed)


def _means(records: list, unseen: dict) -> dict:
    """(method, column, split, persona, task, seed) -> the mean satisfaction rate of that method's records of
    that episode (several sample seeds of one episode are averaged into one paired value)."""
    sums: dict = {}
    for r in records:
        if r.satisfaction_rate is None:
            continue
        for col in split_of(r, unseen):
            s = sums.setdefault((r.agent, col, *_key(r)), [0.0, 0])
            s[0] += r.satisfaction_rate
            s[1] += 1
    return {k: total / n for k, (total, n) in sums.items()}


def paired(records: list, against: str, unseen: dict | None = None) -> list:
    """`PairedRow`s of every method but `against`, per column (seen first), in the order the methods first
    appear; a method or column with no episode in common with the reference has no row."""
    means = _means(records, unseen or {})
    ref: dict = {}
    for (method, col, split, *episode), value in means.items():
        if method == against:
            ref.setdefault((col, *episode), {})[split] = value
    diffs: dict = {}
    for (method, col, split, *episode), value in means.items():
        if method == against:
            continue
        base = _match(ref.get((col, *episode), {}), split)
        if base is not None:
            _persona, task, seed = episode
            diffs.setdefault((method, col), {}).setdefault((split, task, seed), []).append(value - base)
    order = list(dict.fromkeys(r.agent for r in records))
    rows = []
    for (method, col), scenes in diffs.items():
        d = [x for xs in scenes.values() for x in xs]
        m, se = clustered_mean_se(scenes)
        rows.append(PairedRow(method, col, len(d), m, se, sum(x > 0 for x in d), sum(x < 0 for x in d),
                              sum(x == 0 for x in d), len(scenes)))
    return sorted(rows, key=lambda r: (order.index(r.method), r.column != "seen"))


def _match(candidates: dict, split):
    """The reference's value for an episode of `split` among its values by split: the same split's, else the
    only one when either side has no split (an untrained agent); None when there is none or it is ambiguous."""
    if split in candidates:
        return candidates[split]
    if None in candidates:
        return candidates[None]
    if split is None and len(candidates) == 1:
        return next(iter(candidates.values()))
    return None


HEADER = ["Method", "Personas", "Episodes paired", "Scenes", "Difference (points)", "Better / worse / same",
          "Clear (> 2 SE)"]


def cells(row: PairedRow) -> list:
    """The printable cells of a row."""
    return [row.method, row.column, str(row.n), str(row.scenes), f"{row.mean * 100:+.1f} ± {row.se * 100:.1f}",
            f"{row.better} / {row.worse} / {row.same}", "yes" if row.clear else "no"]


def title(against: str) -> str:
    """The line above the table."""
    return (f"Paired with {against} (the same split, persona, task and scene seed): satisfaction minus {against}'s, "
            "mean ± standard error of the per-episode difference, clustered by scene (split, task, scene seed)")


def render_text(rows: list, against: str) -> str:
    """The title and a fixed-width table ('no episode in common' when there is none)."""
    if not rows:
        return f"{title(against)}\n(no episode in common with {against})"
    return f"{title(against)}\n" + fixed_width([HEADER] + [cells(r) for r in rows])


def render_markdown(rows: list, against: str) -> str:
    """The title and a Markdown table."""
    if not rows:
        return f"{title(against)}: no episode in common with {against}."
    return f"{title(against)}.\n\n" + markdown([HEADER] + [cells(r) for r in rows])
