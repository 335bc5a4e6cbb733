"""Evaluation rows, one per method: preference satisfaction rate and questions asked, mean ± standard
error, for seen and unseen personas under the cross-validation splits of the spec (`spec/splits.yaml`:
the release's four 12/4 splits; `CompiledDomain.unseen`); then pass^k over scene seeds and question
precision (`metrics.py`), over all of a method's episodes. A record's method is its `agent` after
`methods.Resolver.resolve`; `papertables.py` lays the rows out as the paper's Table 1 and Table 2."""

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


def table(records: list, unseen: dict | None = None, ks: tuple | None = None) -> list:
    """Rows of `EpisodeRecord`s, one per method (`record.agent`): method, episodes, rate seen/unseen (mean,
    se), questions seen/unseen (mean, se), pass^k for each k in `ks` (default: 1 and the largest k every
    pair has, `default_ks`), question precision and the splits the records were evaluated on. `unseen`
    (the domain's splits) is needed only when some record has a `split`."""
    ks = ks or default_ks(records)
    by_method: dict = {}
    for r in records:
        by_method.setdefault(r.agent, []).append(r)
    return [_row(a, by_method[a], unseen or {}, ks) for a in sorted(by_method, key=_order)]


def default_ks(records: list) -> tuple:
    """(1, K) with K the smallest number of counted episodes every (method, persona, task) pair has; (1,)
    when that is 1 or there is none."""
    k = common_k(records)
    return (1, k) if k and k > 1 else (1,)


def _row(method: str, mine: list, unseen: dict, ks: tuple) -> dict:
    cols = {"seen": ([], []), "unseen": ([], [])}
    for r in mine:
        for col in split_of(r, unseen):
            if r.satisfaction_rate is not None:
                cols[col][0].append(r.satisfaction_rate)
            cols[col][1].append(r.questions)
    return {"agent": method, "episodes": len(mine), "budget": tuple(sorted({r.budget for r in mine})),
            "pass_k": pass_k(mine, ks), "precision": precision(mine),
            "canonical": canonical_counts(mine),
            "rate_seen": mean_se(cols["seen"][0]), "rate_unseen": mean_se(cols["unseen"][0]),
            "questions_seen": mean_se(cols["seen"][1]), "questions_unseen": mean_se(cols["unseen"][1]),
            "splits": tuple(sorted({r.split for r in mine if r.split is not None}))}


_PAPER_ORDER = ["never-ask-llm", "never-ask", "planner", "baseline", "react", "star-gate", "reflection-dpo",
                "no-reflection", "no-dpo", "always-ask-llm", "always-ask", "teacher", "oracle"]


def _order(agent: str) -> tuple:
    return (_PAPER_ORDER.index(agent) if agent in _PAPER_ORDER else len(_PAPER_ORDER), agent)


def _pct(ms) -> str:
    return "n/a" if ms[0] is None else f"{ms[0] * 100:.1f}% ± {ms[1] * 100:.1f}%"


def _num(ms) -> str:
    return "n/a" if ms[0] is None else f"{ms[0]:.1f} ± {ms[1]:.1f}"


HEADER = ["Method", "Episodes", "Steps", "Satisfaction (seen)", "Satisfaction (unseen)", "Questions (seen)",
          "Questions (unseen)"]
METRICS_HEADER = ["Question precision"]


def header(ks: tuple) -> list:
    """Column titles of rows computed with pass^k for `ks`."""
    return HEADER + [f"pass^{k}" for k in ks] + METRICS_HEADER


def ks_of(rows: list) -> tuple:
    """The k values the rows were computed with ((1,) for no rows)."""
    return rows[0]["pass_k"].ks if rows else (1,)


def _pass(pk, k: int) -> str:
    rate = pk.rate(k)
    return "n/a" if rate is None else f"{rate * 100:.1f}%"


def _precision(pr) -> str:
    return "n/a" if pr.rate is None else f"{pr.rate * 100:.1f}% ({pr.precise}/{pr.judged})"


def _budget(row: dict) -> str:
    return "/".join(map(str, row.get("budget") or ())) or "n/a"


def budgets(records: list) -> dict:
    """Step budget -> the methods (record agents) with records at that budget."""
    out: dict = {}
    for r in records:
        out.setdefault(r.budget, set()).add(r.agent)
    return out


def mixed_budgets(records: list) -> str | None:
    """None when every record ran at one step budget; else one line naming each budget's methods."""
    by = budgets(records)
    if len(by) <= 1:
        return None
    parts = "; ".join(f"{b} steps: {', '.join(sorted(m))}" for b, m in sorted(by.items()))
    return (f"these results ran at different step budgets ({parts}): a table compares one budget (re-run the "
            f"rows with the same --max-steps, e.g. `adapt rollout ... --max-steps {max(by)}`) or pass --allow-mixed")


def cells(row: dict) -> list:
    """The printable cells of a row."""
    return ([row["agent"], str(row["episodes"]), _budget(row), _pct(row["rate_seen"]), _pct(row["rate_unseen"]),
             _num(row["questions_seen"]), _num(row["questions_unseen"])]
            + [_pass(row["pass_k"], k) for k in row["pass_k"].ks] + [_precision(row["precision"])])


def notes(rows: list) -> list:
    """Lines said under the table: which k, pairs left out of pass^k, questions in records too old to judge."""
    out = []
    ks = ks_of(rows)
    if rows:
        out.append("pass^k (tau-bench): the chance that k scene seeds of a (persona, task) pair all satisfy every "
                   f"applicable preference, averaged over pairs; k={max(ks)} is the most seeds every (method, persona, "
                   "task) pair has" if max(ks) > 1 else "pass^1: the share of episodes satisfying every applicable "
                   "preference (some (method, persona, task) pair has one seed, so no larger k for every row)")
    left = sum(r["pass_k"].left_out for r in rows)
    if left:
        out.append(f"{left} (method, persona, task) pair(s) had no applicable preference in any seed and are "
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
    return fixed_width([header(ks_of(rows))] + [cells(r) for r in rows])


def fixed_width(data: list) -> str:
    """Rows of cells as left-aligned columns."""
    widths = [max(len(r[i]) for r in data) for i in range(len(data[0]))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in data)


def markdown(data: list) -> str:
    """Rows of cells (the first the header) as a Markdown table."""
    lines = ["| " + " | ".join(data[0]) + " |", "|" + "---|" * len(data[0])]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in data[1:]])


def render_markdown(rows: list) -> str:
    """A Markdown table."""
    return markdown([header(ks_of(rows))] + [cells(r) for r in rows])


CSV_HEADER = ["agent", "episodes", "max_steps", "rate_seen", "rate_seen_se", "rate_unseen", "rate_unseen_se", "questions_seen",
              "questions_seen_se", "questions_unseen", "questions_unseen_se"]
METRICS_CSV_HEADER = ["pass_k_pairs", "pass_k_left_out", "question_precision", "questions_precise",
                      "questions_judged", "questions_repeat", "questions_off"]


def csv_header(ks: tuple) -> list:
    """CSV column names of rows computed with pass^k for `ks`."""
    return CSV_HEADER + [f"pass_{k}" for k in ks] + METRICS_CSV_HEADER


def csv_text(header: list, rows: list) -> str:
    """Quoted CSV (the csv module); None becomes an empty cell, floats keep 6 significant digits."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for row in rows:
        w.writerow(["" if x is None else f"{x:.6g}" if isinstance(x, float) else x for x in row])
    return buf.getvalue().rstrip("\n")


def csv_cells(row: dict) -> list:
    """The CSV values of a row (numbers; None where there is nothing to average)."""
    return [row["agent"], row["episodes"], _budget(row), *row["rate_seen"], *row["rate_unseen"], *row["questions_seen"],
            *row["questions_unseen"], *_metric_cells(row)]


def render_csv(rows: list) -> str:
    """CSV with numeric columns (empty where there is nothing to average)."""
    return csv_text(csv_header(ks_of(rows)), [csv_cells(r) for r in rows])


def _metric_cells(row: dict) -> list:
    pk, pr = row["pass_k"], row["precision"]
    return [*pk.rates, max(pk.pairs, default=0), pk.left_out, pr.rate, pr.precise, pr.judged, pr.repeat, pr.off]
