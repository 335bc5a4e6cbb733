"""Training rows of each method from `adapt train data`'s output (`pairs.jsonl`, read whole: it holds every
considered step, the trainable ones and the skipped ones with their reason).

- `dpo`: rows of kind question or teacher; chosen (the question or a^t) against rejected (a^s).
- `sft` ("no DPO"): the same rows, the chosen completion as the supervised target.
- `no-reflection`: every step that reached the decision rule (kind question or teacher, and skipped
  `no_gain` unless told otherwise), chosen a^t, rejected a^s: the teacher's actions, never a question.
"""

from __future__ import annotations

from pathlib import Path

from ...errors import AdaptError
from ..dataset import TRAINABLE, bad_rows_error, read_problem, read_rows, row_key, skipped_note
from .encode import Encoded, Encoder, action_of


class DataError(AdaptError):
    """Training data that cannot be used (missing, unfinished, malformed): a failure."""

    exit_code = 1


def read_pairs(data, vocab: int | None = None, skip_bad: bool = False, log=None) -> tuple:
    """(rows, bad rows left out) of DATA/pairs.jsonl, once `adapt train data` has finished (DATA/summary.json
    written). Every line is checked (`trainable_problem`, token ids below `vocab`): a bad one is a `BadRows`
    error naming it by file:line, unless `skip_bad`, which leaves the bad rows out and reports them
    through `log`."""
    d = Path(data)
    pairs, summary = d / "pairs.jsonl", d / "summary.json"
    if not pairs.is_file():
        raise DataError(f"--data {data}: no pairs.jsonl (build it with `adapt train data --out {data}`)")
    if not summary.is_file():
        raise DataError(f"--data {data}: `adapt train data` has not finished (no summary.json); run the same "
                        "command again to complete it")
    rows, bad, torn = read_rows(pairs, lambda r: trainable_problem(r, vocab))
    if torn:
        bad.append((len(pairs.read_bytes().split(b"\n")), "a torn last line (no newline, not a row)"))
    if bad and not skip_bad:
        raise bad_rows_error(pairs, bad)
    if bad and log:
        log(skipped_note(pairs, bad))
    return rows, len(bad)


def trainable_problem(row, vocab: int | None = None) -> str | None:
    """What makes a pairs.jsonl row unusable for training (the dataset contract, the prompt's messages,
    the completions' `Action: ` form, the student's token ids within the vocabulary), or None."""
    why = read_problem(row)
    if why:
        return why
    prompt = row["prompt"]
    if not isinstance(prompt, list) or not prompt or not all(
            isinstance(m, dict) and isinstance(m.get("role"), str) and isinstance(m.get("content"), str) for m in prompt):
        return "prompt must be a non-empty list of {role, content} messages"
    for name in ("chosen", "rejected") if row["chosen"] is not None else ("rejected",):
        try:
            action_of(row[name] if isinstance(row[name], list) else None)
            if not isinstance(row[name][-1]["content"], str):
                raise ValueError("its content must be text")
        except (ValueError, TypeError, KeyError, AttributeError) as exc:
            return f"{name}: {exc}"
    if not isinstance(row["teacher_action"], str):
        return "teacher_action must be text"
    return _ids_problem(row.get(GENERATED), vocab)


def _ids_problem(ids, vocab: int | None) -> str | None:
    if ids is None:
        return None
    if not isinstance(ids, list) or not ids or not all(isinstance(t, int) and not isinstance(t, bool) for t in ids):
        return f"{GENERATED} must be a non-empty list of token ids"
    out = [t for t in ids if t < 0 or (vocab is not None and t >= vocab)]
    if out:
        return f"{GENERATED} holds {len(out)} id(s) outside the vocabulary 0..{(vocab or 1) - 1} (first: {out[0]})"
    return None


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


def correction(row: dict, chosen: str) -> tuple:
    """What a row corrects, for `first_corrections`: its episode (persona, task, scene seed, split, interaction) and
    what the chosen action does, as the oracle matches its plan's steps (`agents.scripted.step_effect`: instance
    numbers and a move's source dropped; `sink_1` and `sink_0` are both the sink)."""
    from ...agents.scripted import step_effect

    return (row.get("persona"), row.get("task"), row.get("seed"), row.get("split"), row.get("interaction"),
            step_effect(chosen))


def first_corrections(rows: list, chosen_of) -> tuple:
    """(the rows with only the first, by step, of each episode's rows that choose the same action; how many were
    left out). A student that does not take a correction is given it again at every later step, each time
    against whatever it did instead: the repeats weigh one correction by how long it was ignored, and their
    rejected sides are the student's own other steps (`--dedupe-corrections`)."""
    seen, out = set(), []
    for r in sorted(rows, key=lambda r: r.get("step", 0)):
        key = correction(r, chosen_of(r))
        if key not in seen:
            seen.add(key)
            out.append(r)
    kept = {id(r) for r in out}
    return [r for r in rows if id(r) in kept], len(rows) - len(out)


def mask_forced_rows(rows: list, tokenizer, questions) -> tuple:
    """(rows with keep masks, completion tokens they skip): in each completion, chosen and rejected, the tokens
    of a bank question that the bank forces carry no loss (`--mask-forced`, `training.forced_tokens`): under
    constrained decoding their probability is 1, so the loss is left on asking or acting and on the tokens
    where two questions part."""
    from dataclasses import replace

    from ..forced_tokens import completion_keep, question_trie

    trie, eos = question_trie(tokenizer, questions), tokenizer.eos_token_id
    out, skipped = [], 0
    for r in rows:
        chosen = completion_keep(r.chosen, trie, eos)
        rejected = None if r.rejected is None else completion_keep(r.rejected, trie, eos)
        skipped += chosen.count(0) + (rejected.count(0) if rejected else 0)
        out.append(replace(r, chosen_keep=chosen, rejected_keep=rejected))
    return out, skipped
