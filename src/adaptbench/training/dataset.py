"""The reflection dataset on disk: `pairs.jsonl` (one object per considered step, appended as it goes,
read back to resume) and, at the end, `dataset/` (a Hugging Face `datasets` folder of the trainable rows:
kind question or teacher) and `summary.json` (the mix).

    store = PairStore(out)
    if not store.done(key): store.append(row)
    summary = store.finish()
"""

from __future__ import annotations

import json
import statistics
from collections import Counter
from pathlib import Path

TRAINABLE = ("question", "teacher")
FIELDS = ("prompt", "chosen", "rejected", "kind", "skip_reason", "teacher_action", "student_action", "question",
          "answer", "question_source", "p_teacher", "p_teacher_given_answer", "p_student", "delta_q", "delta_t",
          "eps1", "eps2", "prompt_tokens", "truncated", "spec_hash", "split", "persona", "task", "seed",
          "interaction", "step", "prior", "student_model", "teacher", "teacher_model", "rejected_token_ids",
          "rejected_canonical", "score_dtype", "teacher_preferences", "teacher_reason")


def row_key(row: dict) -> tuple:
    """What identifies a considered step (resuming skips the keys already written)."""
    return (row["persona"], row["task"], row["seed"], row["interaction"], row["step"])


def check_row(row: dict) -> None:
    """ValueError unless the row has every field of the dataset contract and a coherent kind."""
    missing = [f for f in FIELDS if f not in row]
    if missing:
        raise ValueError(f"pair row lacks {', '.join(missing)}")
    if row["kind"] not in ("question", "teacher", "skipped"):
        raise ValueError(f"unknown pair kind '{row['kind']}'")
    if (row["kind"] == "skipped") != (row["chosen"] is None):
        raise ValueError("a skipped row has no chosen completion, and only a skipped row")


class PairStore:
    """`pairs.jsonl` under `out`: rows appended and flushed one by one; a torn last line (a kill mid-write)
    is dropped on reopening."""

    def __init__(self, out):
        self.out = Path(out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.path = self.out / "pairs.jsonl"
        self.rows = self._read()
        self.keys = {row_key(r) for r in self.rows}

    def _read(self) -> list:
        if not self.path.is_file():
            return []
        rows, good = [], 0
        with self.path.open("rb") as f:
            for line in f:
                try:
                    rows.append(json.loads(line))
                except ValueError:
                    break
                good += len(line)
        with self.path.open("r+b") as f:  # cut a torn last line so appends start on a clean line
            f.truncate(good)
        return rows

    def done(self, key: tuple) -> bool:
        """Whether a step of this key is already written."""
        return tuple(key) in self.keys

    def append(self, row: dict) -> None:
        """Check the row and write it as one line (flushed)."""
        check_row(row)
        with self.path.open("a", encoding="utf-8") as f:
            f.write(json.dumps(row, ensure_ascii=False) + "\n")
        self.rows.append(row)
        self.keys.add(row_key(row))

    def finish(self) -> dict:
        """Write `dataset/` (trainable rows) and `summary.json`; returns the summary."""
        from datasets import Dataset

        train = [r for r in self.rows if r["kind"] in TRAINABLE]
        if train:
            Dataset.from_list(train).save_to_disk(str(self.out / "dataset"))
        summary = summarise(self.rows)
        (self.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
        return summary


def summarise(rows: list) -> dict:
    """The mix: counts by kind and skip reason, shares of questions and teacher actions, prompt-token
    statistics, rows truncated and rows still over `--max-length` with only the last step left
    (`over_budget`: kept and flagged, never cut silently; none is ever dropped), rejected answers with
    canonical / non-canonical / no generated ids, and the precision the probabilities were scored in."""
    kinds = Counter(r["kind"] for r in rows)
    reasons = Counter(r["skip_reason"] for r in rows if r["kind"] == "skipped")
    tokens = [r["prompt_tokens"] for r in rows]
    n = len(rows)
    return {"pairs": n, "trainable": kinds["question"] + kinds["teacher"], "kinds": dict(kinds),
            "skip_reasons": dict(reasons), "share": {k: round(kinds[k] / n, 4) if n else 0.0 for k in KINDS_ALL},
            "question_sources": dict(Counter(r["question_source"] for r in rows if r["kind"] == "question")),
            "prompt_tokens": {"min": min(tokens), "max": max(tokens), "mean": round(statistics.fmean(tokens), 1)}
            if tokens else {}, "truncated": sum(bool(r["truncated"]) for r in rows),
            "over_budget": sum(bool(r.get("over_budget")) for r in rows), "dropped": 0,
            "rejected_ids": _canonical_counts(rows),
            "score_dtypes": sorted({r["score_dtype"] for r in rows if r.get("score_dtype")}),
            "scene_seeds": sorted({r["seed"] for r in rows}), **_qa(rows), "delta_q": _quantiles(rows, "delta_q")}


def _qa(rows: list) -> dict:
    """Questions and answers in the rows' full prompts, those the fitted prompts kept, and the rows that
    lost any (0 unless rows were written before fitting kept them: then they are unknown)."""
    known = [r for r in rows if r.get("qa_total") is not None]
    return {"qa_total": sum(r["qa_total"] for r in known), "qa_kept": sum(r["qa_kept"] for r in known),
            "rows_lost_qa": sum(r["qa_kept"] < r["qa_total"] for r in known),
            "rows_qa_unknown": len(rows) - len(known)}


def _quantiles(rows: list, key: str) -> dict:
    """min, quartiles and max of a numeric field over the rows that have it ({} for none)."""
    xs = sorted(r[key] for r in rows if isinstance(r.get(key), int | float))
    if not xs:
        return {}
    at = lambda q: round(xs[min(len(xs) - 1, int(q * len(xs)))], 4)  # noqa: E731
    return {"n": len(xs), "min": round(xs[0], 4), "q25": at(0.25), "median": at(0.5), "q75": at(0.75),
            "max": round(xs[-1], 4), "above_eps1": sum(x > (rows[0].get("eps1") or 0.2) for x in xs)}


def _canonical_counts(rows: list) -> dict:
    """Rejected answers whose generated ids are / are not the tokenizer's own encoding, and rows
    without ids (written before they were recorded, or by a backend that returns none)."""
    flags = Counter(r.get("rejected_canonical") for r in rows)
    return {"canonical": flags[True], "non_canonical": flags[False], "unknown": flags[None]}


KINDS_ALL = ("question", "teacher", "skipped")


def mix_line(summary: dict) -> str:
    """The mix as one line for the terminal."""
    s, k = summary["share"], summary["kinds"]
    reasons = ", ".join(f"{r} {c}" for r, c in sorted(summary["skip_reasons"].items())) or "none"
    return (f"{summary['pairs']} steps: {k.get('question', 0)} questions ({s['question']:.0%}), "
            f"{k.get('teacher', 0)} teacher actions ({s['teacher']:.0%}), {k.get('skipped', 0)} skipped "
            f"({reasons}); {summary['truncated']} prompts shrunk to --max-length, "
            f"{summary.get('rows_lost_qa', 0)} lost a question or answer, 0 dropped")
