"""The paper's Table 1 and Table 2 from per-method rows (`evaluate.table`): each paper row filled by the
first of its candidate methods with records (`methods.fill`), a row without results shown as missing
(never as zero), the methods no row takes listed under "Other methods", and with `paper=True` the
published figures beside ours."""

from __future__ import annotations

from .evaluate import cells, csv_cells, csv_header, csv_text, fixed_width, header, ks_of, markdown
from .methods import TABLES, fill, others

MISSING = "missing"
PAPER_HEADER = ["Paper (seen)", "Paper (unseen)", "Paper questions (seen / unseen)"]
TRAINED = ("star-gate", "reflection-dpo", "no-reflection", "no-dpo")


def sections(rows: list) -> list:
    """[(title, [(paper row or None, our row or None)])]: Table 1, Table 2, then other methods."""
    by_method = {r["agent"]: r for r in rows}
    out = [(title, [(prow, by_method.get(m)) for prow, m in fill(by_method, table)]) for title, table in TABLES]
    rest = others(by_method)
    if rest:
        out.append(("Other methods", [(None, by_method[m]) for m in rest]))
    return out


def _paper_cells(prow) -> list:
    if prow is None:
        return ["", "", ""]
    (rs, rse), (ru, rue), (qs, qse), (qu, que) = prow.paper
    return [f"{rs:.1f}% ± {rse:.1f}%", f"{ru:.1f}% ± {rue:.1f}%", f"{qs:.1f} ± {qse:.1f} / {qu:.1f} ± {que:.1f}"]


def _line(prow, row, width: int, paper: bool) -> list:
    """The cells of one line: the paper row's id, then our cells (or 'missing'), then the paper's."""
    ours = cells(row) if row is not None else [MISSING] + ["—"] * (width - 1)
    return [prow.id if prow else ""] + ours + (_paper_cells(prow) if paper else [])


def _data(rows: list, section: list, paper: bool) -> list:
    head = ["Paper row"] + header(ks_of(rows)) + (PAPER_HEADER if paper else [])
    width = len(header(ks_of(rows)))
    return [head] + [_line(prow, row, width, paper) for prow, row in section]


def render_text(rows: list, paper: bool = False) -> str:
    """Table 1, Table 2 and the other methods as fixed-width tables, each under its title."""
    return "\n\n".join(f"{title}\n{fixed_width(_data(rows, section, paper))}" for title, section in sections(rows))


def render_markdown(rows: list, paper: bool = False) -> str:
    """The same as Markdown: a heading and a table per section."""
    return "\n\n".join(f"**{title}**\n\n{markdown(_data(rows, section, paper))}" for title, section in sections(rows))


def render_csv(rows: list) -> str:
    """One CSV: a line per section row (`table`, `paper_row`, our numbers, the paper's numbers); a missing
    row has its method empty, 0 episodes and empty numbers."""
    ks = ks_of(rows)
    head = ["table", "paper_row"] + csv_header(ks) + ["paper_rate_seen", "paper_rate_seen_se", "paper_rate_unseen",
                                                    "paper_rate_unseen_se", "paper_questions_seen",
                                                    "paper_questions_seen_se", "paper_questions_unseen",
                                                    "paper_questions_unseen_se"]
    width = len(csv_header(ks))
    lines = []
    for title, section in sections(rows):
        for prow, row in section:
            ours = csv_cells(row) if row is not None else ["", 0] + [None] * (width - 2)
            theirs = [x for pair in prow.paper for x in pair] if prow else [None] * 8
            lines.append([title, prow.id if prow else "", *ours, *theirs])
    return csv_text(head, lines)


def notes(rows: list) -> list:
    """Lines under the tables: missing rows, and trained methods whose records carry no split."""
    out = []
    missing = list(dict.fromkeys(prow.id for _, section in sections(rows) for prow, row in section
                                 if prow and row is None))
    if missing:
        out.append(f"missing (no records): {', '.join(missing)}")
    for r in rows:
        if r["agent"] in TRAINED and not r["splits"]:
            out.append(f"{r['agent']}: trained, but no record says on which split (`split` in the record, `split` in "
                       "the model's training.json, or --method NAME@SPLIT=FILE); its episodes count as seen and unseen")
    return out
