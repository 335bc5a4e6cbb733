"""Timing helpers shared by the benchmarks."""

from __future__ import annotations

import statistics
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "spec"


def timeit(fn, repeat: int = 5, number: int = 1) -> float:
    """Median seconds per call of `fn` over `repeat` rounds of `number` calls."""
    rounds = []
    for _ in range(repeat):
        t = time.perf_counter()
        for _ in range(number):
            fn()
        rounds.append((time.perf_counter() - t) / number)
    return statistics.median(rounds)


def episode_actions(name: str = "fifty_steps.txt") -> list:
    """The actions of an example episode."""
    lines = (ROOT / "examples" / name).read_text().splitlines()
    return [ln for ln in lines if ln.strip() and not ln.startswith("#")]


def report(rows: list) -> None:
    """Print benchmark rows: (name, value, unit, target, comparison)."""
    for name, value, unit, target, comparison in rows:
        print(f"{name:<46} {value:>10.4g} {unit:<9} target {target:<12} {comparison}")
