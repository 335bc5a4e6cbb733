"""Faults, measured as a user meets them (whole `adapt rollout` processes):

- seconds from Ctrl-C (SIGINT) to exit of a rollout with two workers;
- random SIGKILLs of the rollout's process group (some leaving a torn last line, as a kill mid-write
  does), each followed by a resume: episodes lost and duplicated against the expected grid;
- with `--against REF`: rollout throughput of this checkout and of git revision REF, interleaved in
  one run (the same grid, two workers, whole process).

    python bench/bench_faults.py [--quick] [--kills N] [--against REF]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "spec"


def _adapt(args: list, src: Path = ROOT / "src", **kw) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(src)}
    return subprocess.Popen([sys.executable, "-m", "adaptbench.cli", *map(str, args)], cwd=ROOT, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, **kw)


def _grid(out: Path, personas: str, seeds: str, workers: int = 2, spec: Path = SPEC) -> list:
    return ["rollout", "--spec", spec, "--agent", "oracle", "--personas", personas, "--tasks", "all",
            "--seeds", seeds, "--out", out, "--workers", workers, "--quiet"]


def _lines(path: Path) -> int:
    return path.read_bytes().count(b"\n") if path.exists() else 0


def _keys(path: Path) -> list:
    out = []
    for line in path.read_bytes().split(b"\n")[:-1]:
        r = json.loads(line)
        out.append((r["agent"], r["persona"], r["task"], r["seed"]))
    return out


def ctrl_c_seconds(tmp: Path, trials: int) -> list:
    """Seconds from SIGINT to exit, once two episodes are written, for `trials` runs."""
    took = []
    for i in range(trials):
        out = tmp / f"int{i}.jsonl"
        p = _adapt(_grid(out, "juan,sarah,lisa", "0-3"))
        end = time.monotonic() + 120
        while _lines(out) < 2 and p.poll() is None and time.monotonic() < end:
            time.sleep(0.02)
        t = time.monotonic()
        os.kill(p.pid, signal.SIGINT)
        p.communicate(timeout=30)
        took.append(time.monotonic() - t)
        assert p.returncode == 130, f"exit code {p.returncode} after Ctrl-C"
    return took


def kills(tmp: Path, n: int, seed: int = 8) -> dict:
    """`n` SIGKILLs at random moments (half leave a torn tail), then a resume to completion."""
    rng = random.Random(seed)
    out = tmp / "kill.jsonl"
    args = _grid(out, "juan,sarah", "0-2")
    for _ in range(n):
        p = _adapt(args)
        time.sleep(rng.uniform(0.3, 3.0))
        os.killpg(p.pid, signal.SIGKILL)
        p.communicate()
        if out.exists() and rng.random() < 0.5:
            with open(out, "ab") as f:
                f.write(b'{"agent": "oracle", "persona": "tor')
    p = _adapt(args)
    _, err = p.communicate(timeout=600)
    assert p.returncode == 0, err
    done = _keys(out)
    expected = 2 * 8 * 3
    return {"kills": n, "expected": expected, "lost": expected - len(set(done)), "duplicated": len(done) - len(set(done))}


def _checkout(tmp: Path, ref: str | None) -> Path:
    if ref is None:
        return ROOT
    path = tmp / f"ref-{len(list(tmp.glob('ref-*')))}"
    subprocess.run(["git", "worktree", "add", "-q", "--detach", str(path), ref], cwd=ROOT, check=True)
    return path


def throughput(tmp: Path, ref: str, rounds: int, this: str | None = None) -> dict:
    """Episodes per second of this checkout (or revision `this`) and of `ref`, whole `adapt rollout`
    processes on the same spec, interleaved round by round."""
    sides = {"now": _checkout(tmp, this), ref: _checkout(tmp, ref)}
    try:
        times: dict = {name: [] for name in sides}
        for r in range(rounds):
            for name, root in sides.items():
                src = root / "src"
                out = tmp / f"tp-{name}-{r}.jsonl"
                t = time.monotonic()
                p = _adapt(_grid(out, "all", "0", spec=root / "spec"), src=src)
                _, err = p.communicate(timeout=900)
                assert p.returncode == 0, err
                times[name].append(time.monotonic() - t)
        return {k: 128 / statistics.median(v) for k, v in times.items()}
    finally:
        for root in sides.values():
            if root != ROOT:
                subprocess.run(["git", "worktree", "remove", "--force", str(root)], cwd=ROOT, check=False)


def main() -> int:
    """Measure and print."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="one Ctrl-C trial and two kills")
    ap.add_argument("--kills", type=int, default=16, help="SIGKILLs before the resume (default 16)")
    ap.add_argument("--against", metavar="REF", help="also compare rollout throughput with git revision REF")
    ap.add_argument("--this", metavar="REF", help="measure revision REF instead of the working tree")
    ap.add_argument("--rounds", type=int, default=3, help="throughput rounds per side (default 3)")
    ap.add_argument("--throughput-only", action="store_true", help="skip the Ctrl-C and kill measurements")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        if not a.throughput_only:
            faults(a, tmp)
        if a.against:
            tp = throughput(tmp, a.against, a.rounds, a.this)
            now, ref = tp["now"], tp[a.against]
            print(f"rollout throughput (oracle, 128 episodes, 2 workers, whole process): {a.this or 'now'} {now:.1f} "
                  f"ep/s, {a.against} {ref:.1f} ep/s ({now / ref:.2f}x)")
    return 0


def faults(a, tmp: Path) -> None:
    """Ctrl-C latency and kills survived."""
    took = ctrl_c_seconds(tmp, 1 if a.quick else 5)
    print(f"Ctrl-C to exit, 2 workers: median {statistics.median(took):.2f} s, max {max(took):.2f} s "
          f"over {len(took)} runs (target < 3 s)")
    k = kills(tmp, 2 if a.quick else a.kills)
    print(f"kills survived: {k['kills']} SIGKILLs + resume: {k['expected']} episodes expected, "
          f"lost {k['lost']}, duplicated {k['duplicated']}")


if __name__ == "__main__":
    sys.exit(main())
