"""Before/after benchmarks measured in the same run: this tree against earlier commits.

    python -m bench.compare                       # after = this tree, before = 5440e37, regex = 668fe89
    python -m bench.compare --skip-grid           # the simulator only (seconds, not minutes)

Each side is checked out into a temporary git worktree (`git worktree add --detach`, removed at the
end) and measured in its own subprocesses with its own source and spec (`PYTHONPATH=<side>/src`, a
separate compiled-domain cache), the sides interleaved so load on the machine hits them alike:

- simulator steps/s on the replayed 50-step episode (`examples/fifty_steps.txt`, a new Env each
  replay, full scene): warm (the parser's cache by text filled, as in a rollout) and cold (the
  cache cleared before each replay). `regex` is the commit before the simulator parsed with the
  grammar (the regex path, kept since only as a test oracle); target: after >= 0.8x regex.
- the oracle grid: every persona x task (128 pairs) x 4 seeds on 2 workers, as a whole process
  (`adapt rollout --agent oracle`), wall-clock; target: after no slower than before. The two sides'
  verdicts are compared episode by episode.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROBE = r'''
import json, sys, time
from pathlib import Path
from adaptbench.compiler import load_domain
from adaptbench.runtime.env import Env

reps = int(sys.argv[1])
domain = load_domain("spec")
actions = [l for l in Path("examples/fifty_steps.txt").read_text().splitlines() if l.strip() and not l.startswith("#")]

def replay(cold):
    env = Env(domain, task="toast_coffee", persona=None, full_scene=True)
    env.reset()
    index = getattr(env, "index", None)
    if cold and index is not None:
        index.parser.parse.cache_clear()
    t = time.perf_counter()
    for a in actions:
        env.step(a)
    return time.perf_counter() - t

replay(False)
out = {}
for mode in ("warm", "cold"):
    times = sorted(replay(mode == "cold") for _ in range(reps))
    out[mode] = len(actions) / times[len(times) // 2]
print(json.dumps(out))
'''


def _git(*args, cwd=ROOT) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True, text=True).stdout


class Side:
    """One version of the code: a directory with src/, spec/, examples/ and its own cache."""

    def __init__(self, name: str, root: Path, cache: Path):
        self.name, self.root, self.cache = name, root, cache

    def env(self) -> dict:
        """The environment its subprocesses run with."""
        return {**os.environ, "PYTHONPATH": str(self.root / "src"), "ADAPT_CACHE": str(self.cache)}

    def run(self, args: list, timeout: float = 3600) -> subprocess.CompletedProcess:
        """Run `python ARGS` in this side's root."""
        return subprocess.run([sys.executable, *args], cwd=self.root, env=self.env(), capture_output=True,
                              text=True, timeout=timeout, check=False)


def _checkout(ref: str, tmp: Path) -> Path:
    path = tmp / f"wt-{ref}"
    _git("worktree", "add", "--detach", "--quiet", str(path), ref)
    return path


def simulator(sides: list, reps: int, rounds: int) -> dict:
    """Steps/s per side (median over rounds of interleaved subprocess runs)."""
    got: dict = {s.name: {"warm": [], "cold": []} for s in sides}
    for _ in range(rounds):
        for s in sides:
            p = s.run(["-c", PROBE, str(reps)], timeout=600)
            if p.returncode:
                raise RuntimeError(f"{s.name}: simulator probe failed:\n{p.stderr[-2000:]}")
            res = json.loads(p.stdout.strip().splitlines()[-1])
            for mode in ("warm", "cold"):
                got[s.name][mode].append(res[mode])
    return {name: {m: statistics.median(v) for m, v in modes.items()} for name, modes in got.items()}


def grid(sides: list, seeds: str, workers: int, tmp: Path) -> dict:
    """Wall-clock seconds of the oracle grid per side, and the records' verdicts."""
    out = {}
    for s in sides:
        warm = s.run(["-m", "adaptbench.cli", "rollout", "--agent", "oracle", "--personas", "all", "--tasks",
                      "eggs", "--seeds", "0", "--out", str(tmp / f"warm-{s.name}.jsonl"), "--quiet"])
        if warm.returncode:
            raise RuntimeError(f"{s.name}: warm-up failed:\n{warm.stderr[-2000:]}")
    for s in sides:
        path = tmp / f"grid-{s.name}.jsonl"
        t = time.perf_counter()
        p = s.run(["-m", "adaptbench.cli", "rollout", "--agent", "oracle", "--personas", "all", "--tasks", "all",
                   "--seeds", seeds, "--workers", str(workers), "--out", str(path), "--quiet"])
        wall = time.perf_counter() - t
        if p.returncode:
            raise RuntimeError(f"{s.name}: grid failed:\n{p.stderr[-2000:]}")
        recs = [json.loads(line) for line in path.read_text().splitlines()]
        out[s.name] = {"seconds": wall, "episodes": len(recs),
                       "verdicts": {(r["persona"], r["task"], r["seed"]): (r["satisfaction_rate"], r["n_steps"],
                                                                           tuple(v["verdict"] for v in r["preferences"]))
                                    for r in recs}}
    return out


def main(argv=None) -> int:
    """Check out the sides, measure, print the comparison."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--before-ref", default="5440e37", help="the 'before' commit (default 5440e37)")
    ap.add_argument("--regex-ref", default="668fe89", help="the last commit of the regex action path")
    ap.add_argument("--skip-grid", action="store_true", help="the simulator only")
    ap.add_argument("--seeds", default="0-3")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--reps", type=int, default=15, help="replays per simulator probe")
    ap.add_argument("--rounds", type=int, default=3, help="interleaved probes per side")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="adapt-compare-") as t:
        tmp = Path(t)
        refs = {"regex": args.regex_ref, "before": args.before_ref}
        sides = [Side(n, _checkout(r, tmp), tmp / f"cache-{n}") for n, r in refs.items()]
        sides.append(Side("after", ROOT, tmp / "cache-after"))
        try:
            sim = simulator(sides, args.reps, args.rounds)
            print(f"simulator steps/s, 50-step replay (median of {args.rounds} x {args.reps}):")
            for name, r in sim.items():
                print(f"  {name:<7} warm {r['warm']:>8.0f}   cold {r['cold']:>8.0f}")
            ratio = sim["after"]["warm"] / sim["regex"]["warm"]
            cold = sim["after"]["cold"] / sim["regex"]["cold"]
            print(f"  after / regex: warm {ratio:.2f}x, cold {cold:.2f}x (target >= 0.8x)")
            if not args.skip_grid:
                g = grid([s for s in sides if s.name != "regex"], args.seeds, args.workers, tmp)
                b, a = g["before"], g["after"]
                print(f"oracle grid ({a['episodes']} episodes, {args.workers} workers, whole process):")
                print(f"  before {b['seconds']:.1f} s   after {a['seconds']:.1f} s   after/before "
                      f"{a['seconds'] / b['seconds']:.2f}x (target <= 1.0x)")
                same = b["verdicts"] == a["verdicts"]
                print(f"  verdicts, steps and rates identical episode by episode: {same}")
        finally:
            for s in sides[:-1]:
                _git("worktree", "remove", "--force", str(s.root))
    return 0


if __name__ == "__main__":
    sys.exit(main())
