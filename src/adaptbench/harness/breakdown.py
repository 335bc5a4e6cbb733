"""`adapt eval --by task|persona|preference`: satisfaction and questions per group.

Episodes in which no preference applied have no satisfaction rate; they are counted in their own
column ("no applicable preference") and left out of the mean, never shown as null or nan.
"""

from __future__ import annotations

from collections import defaultdict

from .evaluate import _num, _order, _pct, csv_text, mean_se

BY = ("task", "persona", "preference")


def _episode_rows(records: list, by: str) -> list:
    groups = defaultdict(list)
    for r in records:
        groups[(r.agent, str(getattr(r, by)))].append(r)
    rows = []
    for (agent, group), recs in sorted(groups.items(), key=lambda kv: (_order(kv[0][0]), kv[0][1])):
        rates = [r.satisfaction_rate for r in recs if r.satisfaction_rate is not None]
        rows.append({"agent": agent, by: group, "episodes": len(recs), "rate": mean_se(rates),
                     "questions": mean_se([r.questions for r in recs]),
                     "no_applicable": len(recs) - len(rates)})
    return rows


def _preference_rows(records: list) -> list:
    counts = defaultdict(lambda: {"satisfied": 0, "violated": 0, "inapplicable": 0})
    for r in records:
        for v in r.preferences:  # only well-formed verdicts are read into a record
            counts[(r.agent, f"{r.persona}.{v.get('id')}")][v["verdict"]] += 1
    rows = []
    for (agent, pref), c in sorted(counts.items(), key=lambda kv: (_order(kv[0][0]), kv[0][1])):
        applicable = c["satisfied"] + c["violated"]
        rows.append({"agent": agent, "preference": pref, **c,
                     "rate": c["satisfied"] / applicable if applicable else None})
    return rows


def breakdown(records: list, by: str) -> list:
    """Rows of the `by` table (see the module doc)."""
    if by not in BY:
        raise ValueError(f"--by must be one of {', '.join(BY)}")
    return _preference_rows(records) if by == "preference" else _episode_rows(records, by)


def _cells(row: dict, by: str) -> list:
    if by == "preference":
        rate = "never applicable" if row["rate"] is None else f"{row['rate']:.1%}"
        return [row["agent"], row["preference"], str(row["satisfied"]), str(row["violated"]),
                str(row["inapplicable"]), rate]
    return [row["agent"], row[by], str(row["episodes"]), _pct(row["rate"]), _num(row["questions"]),
            str(row["no_applicable"])]


def header(by: str) -> list:
    """Column titles of the `by` table."""
    if by == "preference":
        return ["Method", "Preference", "Satisfied", "Violated", "Inapplicable", "Satisfaction"]
    return ["Method", by.capitalize(), "Episodes", "Satisfaction", "Questions", "No applicable preference"]


def render_text(rows: list, by: str) -> str:
    """A fixed-width table."""
    data = [header(by)] + [_cells(r, by) for r in rows]
    widths = [max(len(r[i]) for r in data) for i in range(len(data[0]))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in data)


def render_markdown(rows: list, by: str) -> str:
    """A Markdown table."""
    h = header(by)
    return "\n".join(["| " + " | ".join(h) + " |", "|" + "---|" * len(h)]
                     + ["| " + " | ".join(_cells(r, by)) + " |" for r in rows])


def render_csv(rows: list, by: str) -> str:
    """Quoted CSV; an empty rate where nothing applied."""
    if by == "preference":
        return csv_text(["agent", "preference", "satisfied", "violated", "inapplicable", "rate"],
                        [[r["agent"], r["preference"], r["satisfied"], r["violated"], r["inapplicable"], r["rate"]]
                         for r in rows])
    return csv_text(["agent", by, "episodes", "rate", "rate_se", "questions", "questions_se", "no_applicable"],
                    [[r["agent"], r[by], r["episodes"], *r["rate"], *r["questions"], r["no_applicable"]]
                     for r in rows])
