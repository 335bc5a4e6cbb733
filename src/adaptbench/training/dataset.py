"""The reflection dataset on disk: `pairs.jsonl` (one object per considered step, appended as it goes,
read back to resume) and, at the end, `dataset/` (a Hugging Face `datasets` folder of the trainable rows:
kind question or teacher) and `summary.json` (the mix).

    store = PairStore(out)
    if not store.done(key): store.append(row)
    summary = store.finish()
"""

from __future__ import annotations

import json
import os
import statistics
import sys
from collections import Counter
from pathlib import Path

from ..errors import AdaptError

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
    problem = row_problem(row)
    if problem:
        raise ValueError(problem)


KEY_TYPES = (("persona", str), ("task", str), ("seed", int), ("interaction", int), ("step", int))
# what reading a row back needs (resuming, the summary, training): files written before the newest FIELDS
# were added stay readable
READ_FIELDS = ("prompt", "chosen", "rejected", "kind", "skip_reason", "teacher_action", "question_source",
               "prompt_tokens", "truncated", "persona", "task", "seed", "interaction", "step")


def row_problem(row, fields=FIELDS) -> str | None:
    """What is wrong with a `pairs.jsonl` row (not an object, one of `fields` missing, an unknown kind, a key
    of the wrong type), or None."""
    if not isinstance(row, dict):
        return f"a row must be a JSON object (got {type(row).__name__})"
    missing = [f for f in fields if f not in row]
    if missing:
        return f"pair row lacks {', '.join(missing)}"
    if row["kind"] not in ("question", "teacher", "skipped"):
        return f"unknown pair kind '{row['kind']}' (question, teacher or skipped)"
    if (row["kind"] == "skipped") != (row["chosen"] is None):
        return "a skipped row has no chosen completion, and only a skipped row"
    wrong = [k for k, t in KEY_TYPES if not isinstance(row[k], t) or isinstance(row[k], bool)]
    if wrong:
        return f"{', '.join(wrong)} of the wrong type ({', '.join(f'{k} {row[k]!r}' for k in wrong)})"
    return None


def read_problem(row) -> str | None:
    """What makes a row read back from `pairs.jsonl` unusable (`row_problem` on READ_FIELDS), or None."""
    return row_problem(row, READ_FIELDS)


def parse_line(raw: bytes, problem=read_problem) -> tuple:
    """(row, None) for a good line, (None, why) for a bad one (not UTF-8, not JSON, `problem(row)`)."""
    try:
        row = json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        return None, "not UTF-8 text"
    except ValueError as exc:
        return None, f"not JSON ({exc.msg} at column {exc.colno})"
    why = problem(row)
    return (None, why) if why else (row, None)


class BadRows(AdaptError):
    """Lines of a rows file that cannot be used, named by file:line: a usage error (exit 2), unless the
    command is told to skip them (`--skip-bad-rows`)."""

    exit_code = 2


def bad_rows_error(path, bad: list, skip_flag: str = "--skip-bad-rows") -> BadRows:
    """The error naming the bad lines (`bad`: (line number, why); the first three with why) in one line."""
    named = "; ".join(f"{path}:{n}: {why}" for n, why in bad[:3])
    more = f" (and {len(bad) - 3} more bad line(s): {_lines(bad[3:])})" if len(bad) > 3 else ""
    return BadRows(f"{named}{more}; fix or delete the line(s), or pass {skip_flag} to leave the bad row(s) out "
                   "(counted and reported)")


def skipped_note(path, bad: list) -> str:
    """The line that reports the rows `--skip-bad-rows` left out."""
    return f"{path}: left out {len(bad)} bad row(s) (--skip-bad-rows), line(s) {_lines(bad)}; the first: {bad[0][1]}"


def _lines(bad: list, shown: int = 10) -> str:
    nums = [str(n) for n, _ in bad[:shown]]
    return ", ".join(nums) + (", ..." if len(bad) > shown else "")


def read_rows(path: Path, problem=read_problem) -> tuple:
    """(rows, bad, torn) of a JSONL file: the good rows, (line number, why) of each bad line, and whether the
    last line was torn (no newline and not a good row: a kill mid-write)."""
    data = path.read_bytes()
    lines = data.split(b"\n")
    last, lines = lines[-1], lines[:-1]
    rows, bad = [], []
    for n, raw in enumerate(lines, 1):
        if not raw.strip():  # a blank line holds no row
            continue
        row, why = parse_line(raw, problem)
        if why:
            bad.append((n, why))
        else:
            rows.append(row)
    torn = False
    if last.strip():
        row, why = parse_line(last, problem)
        if why:
            torn = True
        else:
            rows.append(row)
    return rows, bad, torn


class PairStore:
    """`pairs.jsonl` under `out`: rows appended and flushed one by one. Reopening it checks every line: a
    torn last line (a kill mid-write) is cut off and said so; any other bad line (`[]`, a row without the
    contract's fields, an unknown kind, not JSON) is a `BadRows` error naming it by file:line, unless
    `skip_bad`: then the bad lines are moved to `pairs.jsonl.bad`, counted and reported through `log`,
    and their steps made again."""

    def __init__(self, out, skip_bad: bool = False, log=None):
        self.out = Path(out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.path = self.out / "pairs.jsonl"
        self.log = log or _stderr
        self.rows = self._read(skip_bad)
        self.keys = {row_key(r) for r in self.rows}
        self.questions = {row_key(r): r["question"] for r in self.rows if r["kind"] == "question"}

    def _read(self, skip_bad: bool) -> list:
        if not self.path.is_file():
            return []
        rows, bad, torn = read_rows(self.path)
        if bad and not skip_bad:
            raise bad_rows_error(self.path, bad)
        if torn:
            self.log(f"{self.path}: cut a torn last line (a kill mid-write); its step is made again")
        if bad:
            lines = self.path.read_bytes().split(b"\n")
            with (self.out / "pairs.jsonl.bad").open("ab") as f:
                f.write(b"".join(lines[n - 1] + b"\n" for n, _ in bad))
            self.log(skipped_note(self.path, bad) + f"; moved to {self.out / 'pairs.jsonl.bad'}, their steps made again")
        if bad or torn or not self._ends_clean():
            self._rewrite({n for n, _ in bad}, torn)
        return rows

    def _ends_clean(self) -> bool:
        size = self.path.stat().st_size
        if not size:
            return True
        with self.path.open("rb") as f:
            f.seek(size - 1)
            return f.read(1) == b"\n"

    def _rewrite(self, bad: set, torn: bool) -> None:
        """pairs.jsonl without the bad lines and the torn tail (the good lines byte for byte), atomically."""
        lines = self.path.read_bytes().split(b"\n")
        last, lines = lines[-1], lines[:-1]
        keep = [raw + b"\n" for n, raw in enumerate(lines, 1) if n not in bad]
        if last.strip() and not torn:
            keep.append(last + b"\n")
        tmp = self.path.with_name("pairs.jsonl.tmp")
        tmp.write_bytes(b"".join(keep))
        os.replace(tmp, self.path)

    def done(self, key: tuple) -> bool:
        """Whether a step of this key is already written."""
        return tuple(key) in self.keys

    def chosen_question(self, key: tuple) -> str | None:
        """The question a written step's row chose (None: it chose none, or is not written)."""
        return self.questions.get(tuple(key))

    def append(self, row: dict) -> None:
        """Check the row and write it as one line (flushed)."""
        check_row(row)
        with self.path.open("a", encoding="utf-8") as f:
            f.write(json.dumps(row, ensure_ascii=False) + "\n")
        self.rows.append(row)
        self.keys.add(row_key(row))
        if row["kind"] == "question":
            self.questions[row_key(row)] = row["question"]

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


def _stderr(msg: str) -> None:
    print(f"adapt: {msg}", file=sys.stderr, flush=True)


def mix_line(summary: dict) -> str:
    """The mix as one line for the terminal."""
    s, k = summary["share"], summary["kinds"]
    reasons = ", ".join(f"{r} {c}" for r, c in sorted(summary["skip_reasons"].items())) or "none"
    return (f"{summary['pairs']} steps: {k.get('question', 0)} questions ({s['question']:.0%}), "
            f"{k.get('teacher', 0)} teacher actions ({s['teacher']:.0%}), {k.get('skipped', 0)} skipped "
            f"({reasons}); {summary['truncated']} prompts shrunk to --max-length, "
            f"{summary.get('rows_lost_qa', 0)} lost a question or answer, 0 dropped")
