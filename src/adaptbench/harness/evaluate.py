"""Evaluation tables in the paper's Table 1 layout: preference satisfaction rate and questions asked,
mean ± standard error, for seen and unseen personas under the cross-validation splits of the spec
(`spec/splits.yaml`: the release's four 12/4 splits; `CompiledDomain.unseen`); then pass^k over scene
seeds and question precision (`metrics.py`), over all of an agent's episodes."""

from __future__ import annotations

import csv
import io
import math

from .metrics import common_k, pass_k, precision
from .modelsteps import canonical_counts, canonical_line


def load_records(paths, splits=None) -> list:
    """All usable episode records from JSONL files (see `records.load_runs` for what is skipped)."""
    from .records import load_runs

    return load_runs(paths, splits).records


def mean_se(values: list) -> tuple:
    """Mean and standard error of the mean; (None, None) for no values."""
    n = len(values)
    if n == 0:
        return None, None
    m = sum(values) / n
    if n == 1:
        return m, 0.0
    var = sum((v - m) ** 2 for v in values) / (n - 1)
    return m, math.sqrt(var / n)


def split_of(record, unseen: dict) -> list:
    """The columns an `EpisodeRecord` counts in: a record with a `split` is seen or unseen in that split
    (`unseen`: split id -> held-out persona ids, the domain's `unseen`); an untrained agent's record
    counts in both columns (every persona is seen in some splits and unseen in one)."""
    if record.split is not None:
        held_out = record.persona in unseen[record.split]
        return ["unseen" if held_out else "seen"]
    return ["seen", "unseen"]


def table(records: list, unseen: dict | None = None) -> list:
    """Rows of `EpisodeRecord`s: agent, n, rate seen/unseen (mean, se), questions seen/unseen (mean, se).
    `unseen` (the domain's splits) is needed only when some record has a `split`."""
    agents = sorted({r.agent for r in records}, key=lambda a: _order(a))
    k = common_k(records)  # one k for every row: the smallest number of seeds every pair has
    rows = []
    for a in agents:
        cols = {"seen": ([], []), "unseen": ([], [])}
        for r in records:
            if r.agent != a:
                continue
            for col in split_of(r, unseen or {}):
                if r.satisfaction_rate is not None:
                    cols[col][0].append(r.satisfaction_rate)
                cols[col][1].append(r.questions)
        mine = [r for r in records if r.agent == a]
        rows.append({"agent": a, "episodes": len(mine), "pass_k": pass_k(mine, k), "precision": precision(mine),
                     "canonical": canonical_counts(mine),
                     "rate_seen": mean_se(cols["seen"][0]), "rate_unseen": mean_se(cols["unseen"][0]),
                     "questions_seen": mean_se(cols["seen"][1]), "questions_unseen": mean_se(cols["unseen"][1])})
    return rows


_PAPER_ORDER = ["never-ask", "baseline", "react", "star-gate", "reflection-dpo", "always-ask", "oracle", "teacher"]


def _order(agent: str) -> tuple:
    return (_PAPER_ORDER.index(agent) if agent in _PAPER_ORDER else len(_PAPER_ORDER), agent)


def _pct(ms) -> str:
    return "n/a" if ms[0] is None else f"{ms[0] * 100:.1f}% ± {ms[1] * 100:.1f}%"


def _num(ms) -> str:
    return "n/a" if ms[0] is None else f"{ms[0]:.1f} ± {ms[1]:.1f}"


HEADER = ["Method", "Episodes", "Satisfaction (seen)", "Satisfaction (unseen)", "Questions (seen)",
          "Questions (unseen)", "pass^k", "Question precision"]


def _pass_k(pk) -> str:
    if pk.rate is None:
        return "n/a"
    return f"{pk.rate * 100:.1f}% ({pk.passed}/{pk.pairs}, k={pk.k_text})"


def _precision(pr) -> str:
    return "n/a" if pr.rate is None else f"{pr.rate * 100:.1f}% ({pr.precise}/{pr.judged})"


def cells(row: dict) -> list:
    """The printable cells of a row."""
    return [row["agent"], str(row["episodes"]), _pct(row["rate_seen"]), _pct(row["rate_unseen"]),
            _num(row["questions_seen"]), _num(row["questions_unseen"]), _pass_k(row["pass_k"]),
            _precision(row["precision"])]


def notes(rows: list) -> list:
    """Lines said under the table: pairs left out of pass^k, questions in records too old to judge."""
    out = []
    ks = {r["pass_k"].k_text for r in rows if r["pass_k"].k_text}
    if len(ks) == 1:
        k = ks.pop()
        out.append(f"pass^k: k={k} for every row, the smallest number of scene seeds every (agent, persona, task) "
                   f"pair has; a pair with more seeds counts its first {k}")
    left = sum(r["pass_k"].left_out for r in rows)
    if left:
        out.append(f"{left} (agent, persona, task) pair(s) had no applicable preference in any seed and are "
                   "left out of pass^k")
    line = canonical_line(rows)
    if line:
        out.append(line)
    old = sum(r["precision"].unjudged for r in rows)
    if old:
        out.append(f"{old} question(s) in records older than version 2 carry no targets and are not judged "
                   "for question precision")
    return out


def render_text(rows: list) -> str:
    """A fixed-width table."""
    data = [HEADER] + [cells(r) for r in rows]
    widths = [max(len(r[i]) for r in data) for i in range(len(HEADER))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in data)


def render_markdown(rows: list) -> str:
    """A Markdown table."""
    lines = ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    lines += ["| " + " | ".join(cells(r)) + " |" for r in rows]
    return "\n".join(lines)


CSV_HEADER = ["agent", "episodes", "rate_seen", "rate_seen_se", "rate_unseen", "rate_unseen_se", "questions_seen",
              "questions_seen_se", "questions_unseen", "questions_unseen_se", "pass_k", "pass_k_passed",
              "pass_k_pairs", "k_min", "k_max", "pass_k_left_out", "question_precision", "questions_precise",
              "questions_judged"]


def csv_text(header: list, rows: list) -> str:
    """Quoted CSV (the csv module); None becomes an empty cell, floats keep 6 significant digits."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for row in rows:
        w.writerow(["" if x is None else f"{x:.6g}" if isinstance(x, float) else x for x in row])
    return buf.getvalue().rstrip("\n")


def render_csv(rows: list) -> str:
    """CSV with numeric columns (empty where there is nothing to average)."""
    return csv_text(CSV_HEADER, [[r["agent"], r["episodes"], *r["rate_seen"], *r["rate_unseen"], *r["questions_seen"],
                                  *r["questions_unseen"], *_metric_cells(r)] for r in rows])


def _metric_cells(row: dict) -> list:
    pk, pr = row["pass_k"], row["precision"]
    k = pk.k or (None, None)
    return [pk.rate, pk.passed, pk.pairs, *k, pk.left_out, pr.rate, pr.precise, pr.judged]
