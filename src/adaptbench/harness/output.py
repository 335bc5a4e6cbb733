"""What a rollout did (`RolloutResult`) and how its records reach the results file: appended as they
come, with a progress bar."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from .results import ResultsFile
from .workers import Interrupted


@dataclass
class RolloutResult:
    """What a rollout did: episodes run, already present, errors, and whether it was interrupted."""

    ran: int = 0
    present: int = 0
    errors: int = 0
    interrupted: bool = False
    error_samples: list = field(default_factory=list)


def write_all(store: ResultsFile, records, total: int, res: RolloutResult, out, progress: bool = True,
              unit: str = "ep") -> None:
    """Append each record as it comes (duplicates skipped), with a progress bar over `total`; on
    `Interrupted` mark `res` and re-raise (what was written stays). With `unit` "step", `records` also
    holds `Ticks` (steps taken, `batches.run_batched(ticks=True)`) and the bar counts steps: it moves
    while long episodes run (a model's episode can take minutes)."""
    from ..progress import progress_bar
    from .episode import Ticks

    bar = progress_bar(total, f"rollout -> {Path(out).name}", unit=unit) if progress else None
    try:
        for record in records:
            if isinstance(record, Ticks):
                if bar:
                    bar.update(record.steps)
                continue
            _write(store, record, bar, res, step=unit == "step")
    except Interrupted:
        res.interrupted = True
        raise
    finally:
        if bar:
            bar.close()


def _write(store: ResultsFile, record: dict, bar, res: RolloutResult, step: bool = False) -> None:
    if not store.append(record):
        return
    res.ran += 1
    if "error" in record:
        res.errors += 1
        if len(res.error_samples) < 3:
            res.error_samples.append(f"{record['agent']} {record['persona']}/{record['task']} seed {record['seed']}: "
                                     f"{record['error']}")
    if bar:
        rate = record.get("satisfaction_rate")
        note = "error" if "error" in record else ("n/a" if rate is None else f"{rate:.0%}")
        bar.set_postfix_str(f"{record['agent']} {record['persona']}/{record['task']} {note}", refresh=False)
        if not step:
            bar.update()
