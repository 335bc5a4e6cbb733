"""Run every benchmark and print one table: `python bench/run_all.py [--quick]`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench import (  # noqa: E402
    bench_grammar,
    bench_rollout,
    bench_simulator,
    bench_student,
    bench_validate,
    bench_verify,
)
from bench.common import report  # noqa: E402


def main() -> int:
    """Run all benchmarks."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (CI)")
    args = parser.parse_args()
    rows = []
    for mod in (bench_validate, bench_simulator, bench_verify, bench_grammar, bench_rollout, bench_student):
        rows.extend(mod.run(quick=args.quick))
    report(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
