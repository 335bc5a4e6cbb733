"""Training rows of each method from `adapt train data`'s output (`pairs.jsonl`, read whole: it holds every
considered step, the trainable ones and the skipped ones with their reason).

- `dpo`: rows of kind question or teacher; chosen (the question or a^t) against rejected (a^s).
- `sft` ("no DPO"): the same rows, the chosen completion as the supervised target.
- `no-reflection`: every step that reached the decision rule (kind question or teacher, and skipped
  `no_gain` unless told otherwise), chosen a^t, rejected a^s: the teacher's actions, never a question.
"""

from __future__ import annotations

import json
from pathlib import Path

from ...errors import AdaptError
from ..dataset import TRAINABLE, row_key
from .encode import Encoded, Encoder, action_of


class DataError(AdaptError):
    """Training data that cannot be used (missing, unfinished, malformed): a failure."""

    exit_code = 1


def read_pairs(data) -> list:
    """The rows of DATA/pairs.jsonl, once `adapt train data` has finished (DATA/summary.json written)."""
    d = Path(data)
    pairs, summary = d / "pairs.jsonl", d / "summary.json"
    if not pairs.is_file():
        raise DataError(f"--data {data}: no pairs.jsonl (build it with `adapt train data --out {data}`)")
    if not summary.is_file():
        raise DataError(f"--data {data}: `adapt train data` has not finished (no summary.json); run the same "
                        "command again to complete it")
    rows = []
    for n, line in enumerate(pairs.read_text(encoding="utf-8").splitlines(), 1):
        try:
            rows.append(json.loads(line))
        except ValueError:
            raise DataError(f"--data {data}: pairs.jsonl line {n} is not JSON") from None
    return rows


GENERATED = "rejected_token_ids"  # the student's generated ids, laid out as TRL's completion (training-data.md)


def _generated(row: dict):
    ids = row.get(GENERATED)
    if ids is None:
        return None
    if not isinstance(ids, list) or not ids or not all(isinstance(t, int) for t in ids):
        raise DataError(f"row {row_key(row)}: {GENERATED} must be a non-empty list of token ids")
    return tuple(ids)


def preference_row(enc: Encoder, row: dict, chosen: str) -> Encoded:
    """A row in ids: the prompt, `chosen`, and the student's action (the ids it generated when the row has
    them and the template allows TRL's layout, which they are laid out in)."""
    prompt, (c, r), trl_layout = enc.row(row["prompt"], chosen, action_of(row["rejected"]))
    generated = _generated(row)
    use = generated is not None and trl_layout
    return Encoded(row_key(row), prompt, c, generated if use else r, bool(row.get("truncated")), use)


def dpo_rows(rows: list, enc: Encoder) -> list:
    """Reflection-DPO's rows: the trainable kinds, chosen as the data step decided."""
    return [preference_row(enc, r, action_of(r["chosen"])) for r in rows if r["kind"] in TRAINABLE]


def sft_rows(rows: list, enc: Encoder) -> list:
    """The "no DPO" rows: the trainable kinds' chosen completions (the rejected one is kept for the
    length check only: an SFT row is prompt + chosen)."""
    out = []
    for r in rows:
        if r["kind"] in TRAINABLE:
            prompt, (chosen,), _ = enc.row(r["prompt"], action_of(r["chosen"]))
            out.append(Encoded(row_key(r), prompt, chosen, None, bool(r.get("truncated"))))
    return out


def reached_rule(row: dict, no_gain: bool = True) -> bool:
    """Whether a step reached the decision rule (the teacher's action differed from the student's, not after
    two failures): kinds question and teacher, and skipped `no_gain` when `no_gain`."""
    return row["kind"] in TRAINABLE or (no_gain and row["kind"] == "skipped" and row["skip_reason"] == "no_gain")


def no_reflection_rows(rows: list, enc: Encoder, no_gain: bool = True) -> list:
    """Table 2's "no Reflection" rows: a^t chosen over a^s at every step that reached the decision rule."""
    return [preference_row(enc, r, r["teacher_action"]) for r in rows if reached_rule(r, no_gain)]
