"""Reading results files for evaluation: every line accounted for.

Each line is read through the typed record schema (`record.EpisodeRecord`, any known version).
Lines that are not usable episodes are skipped and counted by reason (torn or not JSON, not UTF-8,
not an episode record, bad values, a newer record version, an episode that ended in an error, a
duplicate of an episode already read), and the spec hashes of each file are collected so evaluation
can refuse to mix specs. Records written before the schema was versioned are read and counted.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import AdaptError
from .record import EpisodeRecord, RecordError
from .results import episode_key, iter_lines, parse_line


class RunsError(AdaptError):
    """Results files that cannot be evaluated (missing, unreadable, mixed specs); the message says why."""

    def __init__(self, message: str, code: int = 1):
        super().__init__(message, code=code)


@dataclass
class Runs:
    """Usable episode records, what was skipped and why, and the spec hashes found in each file."""

    records: list = field(default_factory=list)  # EpisodeRecord, in file order
    sources: list = field(default_factory=list)  # the file each record was read from (parallel to records)
    skipped: Counter = field(default_factory=Counter)
    hashes: dict = field(default_factory=dict)  # file -> Counter of spec hashes
    unversioned: int = 0  # records written before records carried a version (read as version 0)

    def skipped_text(self) -> str:
        """'skipped 3 line(s): 2 duplicate episode, 1 not JSON (torn line)' or ''."""
        if not self.skipped:
            return ""
        parts = ", ".join(f"{n} {why}" for why, n in self.skipped.most_common())
        return f"skipped {sum(self.skipped.values())} line(s): {parts}"


def _classify(rec, why, seen: set, splits):
    """(record, None) for a usable episode, else (None, the reason it is skipped)."""
    if rec is None:
        return None, why
    try:
        record = EpisodeRecord.from_dict(rec)
    except RecordError as exc:
        return None, str(exc)
    if record.error is not None:
        return None, "episode ended in an error"
    if record.split is not None and not _known_split(record.split, splits):
        return None, "unknown split"
    key = episode_key(rec)
    if key in seen:
        return None, "duplicate episode"
    seen.add(key)
    return record, None


def _known_split(split: int, splits) -> bool:
    """Whether a split id is one of the domain's (`splits`: a mapping, or a callable returning one)."""
    return split in (splits() if callable(splits) else splits or {})


def _check_file(path: Path) -> None:
    if not path.exists():
        raise RunsError(f"no such file: {path}", 2)
    if path.is_dir():
        raise RunsError(f"{path} is a directory; give the JSONL files written by adapt rollout", 2)


def load_runs(paths, splits=None) -> Runs:
    """Read every file; RunsError for a missing or unreadable one. `splits`: the domain's split ids (a
    mapping, or a callable returning one, called only if some record has a `split`); a record whose
    split is not among them is skipped."""
    runs, seen = Runs(), set()
    for p in map(Path, paths):
        _check_file(p)
        hashes = runs.hashes.setdefault(str(p), Counter())
        lines = not_json = 0
        try:
            for _, line in iter_lines(p):
                record, reason = _classify(*parse_line(line), seen, splits)
                lines += 1
                if reason:
                    not_json += reason == "not JSON"
                    runs.skipped[reason] += 1
                    continue
                hashes[record.spec_hash] += 1
                runs.unversioned += record.version == 0
                runs.records.append(record)
                runs.sources.append(str(p))
            tail = p.read_bytes()[-1:]
        except OSError as exc:
            raise RunsError(f"cannot read {p} ({exc.strerror})", 2) from None
        if lines and not_json == lines:
            raise RunsError(f"{p} is not a run record (JSONL written by adapt rollout): none of its {lines} lines is "
                            "a JSON record", 2)
        if tail and tail != b"\n":
            runs.skipped["torn last line"] += 1
    return runs


def mixed_specs(runs: Runs) -> str | None:
    """A message naming the files and their spec hashes when more than one spec is present, else None."""
    every = {h for c in runs.hashes.values() for h in c}
    if len(every) <= 1:
        return None
    lines = [f"  {f}: spec {', '.join(str(h) for h in c)}" for f, c in runs.hashes.items() if c]
    return ("results of different specs (compare like with like, or pass --allow-mixed):\n" + "\n".join(lines))
