"""What the model steps of a set of episodes record about their tokens (`adapt eval` says it under the
table): how many generated token sequences were the tokenizer's own encoding of their text.

A grammar-constrained decoder may take another split of the same bytes than the tokenizer writes
(`quart`+`er`, a forced `_0 ` after `oven`); each model step records `stats.canonical`
(`llm.backend.canonical`). On-policy training must use the recorded `token_ids` of such steps.
"""

from __future__ import annotations


def canonical_counts(records) -> tuple:
    """(steps whose generated ids were canonical, model steps that say) over the records' steps; steps
    without the flag (scripted agents, records written before it, servers that return no ids) are not
    counted."""
    flags = [s.stats["canonical"] for r in records for s in r.steps
             if s.stats and isinstance(s.stats.get("canonical"), bool)]
    return sum(flags), len(flags)


def canonical_line(rows: list) -> str | None:
    """One line naming each agent's canonical-id rate (`rows`: `evaluate.table` rows with `canonical`),
    or None when no row has model steps that record it."""
    parts = [f"{r['agent']} {c}/{n} model steps ({c / n:.0%})" for r in rows for c, n in [r.get("canonical") or (0, 0)]
             if n]
    if not parts:
        return None
    return ("canonical token ids: " + "; ".join(parts) + " (the rest took other token splits of their text: "
            "train on-policy on their recorded token_ids)")
