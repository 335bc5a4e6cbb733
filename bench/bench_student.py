"""The shipped student (`--model student`) against the random tiny model it started from, greedy, on split
0's unseen personas x 8 tasks x scene seed 0 (never trained on): satisfaction, questions, failed steps,
dishes completed.

    python bench/bench_student.py [--out runs/bench-student] [--personas leila,lisa,mark,samantha] [--seeds 0]

Rolls out `adapt rollout --agent planner` with each model into OUT/<name>.jsonl (resumable), then prints one
row per model. The random tiny model is `adapt model init` with its defaults (OUT/tiny).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path


def summary(path: Path, domain) -> dict:
    """Episodes, mean satisfaction (episodes with an applicable preference), questions, failed steps and
    dishes completed of one results file."""
    recs = [json.loads(x) for x in path.read_text().splitlines() if x.strip()]
    recs = [r for r in recs if "steps" in r and "error" not in r]
    rated = [r["satisfaction_rate"] for r in recs if r.get("satisfaction_rate") is not None]
    steps = [s for r in recs for s in r["steps"]]
    dishes = sum(len(domain.task[r["task"]].components) for r in recs)
    return {"episodes": len(recs), "satisfaction": sum(rated) / max(1, len(rated)),
            "questions": sum(r["questions"] for r in recs) / max(1, len(recs)),
            "asking_episodes": sum(1 for r in recs if r["questions"]), "steps": len(steps),
            "failed_steps": sum(1 for s in steps if not s["ok"]),
            "completed": sum(len(r["completed"]) for r in recs), "dishes": dishes}


def _rollout(model: str, out: Path, args) -> float:
    t0 = time.perf_counter()
    subprocess.run(["adapt", "rollout", "--agent", "planner", "--model", model, "--personas", args.personas,
                    "--tasks", "all", "--seeds", args.seeds, "--out", str(out), "--quiet"], check=True)
    return time.perf_counter() - t0


def main(argv=None) -> int:
    """Run both rollouts (resuming) and print the table."""
    from adaptbench.compiler import load_domain

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="runs/bench-student")
    p.add_argument("--personas", default="leila,lisa,mark,samantha")
    p.add_argument("--seeds", default="0")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if not (out / "tiny" / "config.json").is_file():
        subprocess.run(["adapt", "model", "init", "--out", str(out / "tiny")], check=True, stdout=subprocess.DEVNULL)
    domain = load_domain()
    print("| model | episodes | satisfaction | questions / episode | episodes that ask | failed steps | dishes "
          "completed | rollout s |\n|---|---|---|---|---|---|---|---|")
    for name, model in (("random tiny (adapt model init)", str(out / "tiny")), ("student", "student")):
        path = out / f"{'student' if model == 'student' else 'tiny'}.jsonl"
        secs = _rollout(model, path, args)
        s = summary(path, domain)
        print(f"| {name} | {s['episodes']} | {s['satisfaction']:.1%} | {s['questions']:.2f} | "
              f"{s['asking_episodes']} / {s['episodes']} | {s['failed_steps']} / {s['steps']} | "
              f"{s['completed']} / {s['dishes']} | {secs:.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
