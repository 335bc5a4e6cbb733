"""The oracle over the full grid: 16 personas x 8 tasks x 4 seeds (512 episodes) on 2 workers.

Compared with the same grid in one process (what a plain loop would do) and reported as the
oracle's simulations per second (each is a whole simulated episode plus its verdicts).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from adaptbench.compiler import load_domain
from adaptbench.harness.rollout import Job, rollout

from .common import SPEC, report


def _grid(domain, seeds, personas=None) -> list:
    personas = personas or [p.id for p in domain.personas]
    return [Job("oracle", p, t.id, s) for p in personas for t in domain.tasks for s in seeds]


def run(quick: bool = False) -> list:
    """Measure and return report rows."""
    domain = load_domain(SPEC)
    seeds = [0] if quick else [0, 1, 2, 3]
    personas = [p.id for p in domain.personas][: 4 if quick else None]
    jobs = _grid(domain, seeds, personas)
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        rollout(jobs, Path(tmp) / "two.jsonl", workers=2, spec=str(SPEC), progress=False)
        two = time.perf_counter() - t
        sample = jobs[:: max(1, len(jobs) // 16)]
        t = time.perf_counter()
        rollout(sample, Path(tmp) / "one.jsonl", workers=1, spec=str(SPEC), progress=False)
        one = (time.perf_counter() - t) / len(sample) * len(jobs)
    return [(f"oracle grid, {len(jobs)} episodes, 2 workers", two, "s", "< 60 s (512)",
             f"{one / two:.2f}x a single-process loop (est. {one:.0f} s)")]


if __name__ == "__main__":
    report(run())
