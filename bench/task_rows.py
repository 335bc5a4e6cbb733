"""Task-contrast rows: pairs of step-0 prompts that differ only in the task, each with its oracle's first action.

    python bench/task_rows.py --out runs/tasks/rows.jsonl [--personas juan,sarah,...] [--seeds 100-107] [--only tea_eggs]

Every student in this project reads "Make tea and eggs for breakfast" as "Make toast and coffee for
breakfast": it starts with `Look for bread` and makes no tea-and-eggs dish (0 of 32 unseen episodes for
the shipped student and every model trained from it; `adapt probe tasks` reads 7 of 8 tasks right, never
that one). The prompts of two tasks differ in a few tokens, as two answers to a question do. This writes,
for each persona and training scene seed, every pair of tasks whose first actions differ, as two rows with
one key in the answer-row format (`training.answer_rows`, kind "answer"), so that
`bench/cook_and_read.py --row-loss contrast --rows ROWS` trains each task's prompt to score its own first
action above the other task's: a model that ignores the task lowers one side only by raising the other.
The contrast here is between tasks, not answers; the file format is the same. A measurement, not a shipped
training method (docs/training.md).
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path

from answer_context import seed_range  # bench/answer_context.py, beside this file


def task_pair_rows(sc, only: str | None = None) -> list:
    """The rows of one scene (`llm.task_probe.Scene`): for each pair of tasks with different first actions
    (with `only`, the pairs that contain that task), each task's step-0 prompt and its own first action, under
    one key."""
    out = []
    for a, b in itertools.combinations(sorted(sc.prompts), 2):
        if sc.firsts[a] == sc.firsts[b] or (only and only not in (a, b)):
            continue
        key = f"task/{a} vs {b}/{sc.persona}/{sc.seed}"
        for t in (a, b):
            p = sc.prompts[t]
            out.append({"kind": "answer", "key": key, "at": "task", "task": t, "messages": list(p.messages),
                        "prefix": p.prefix, "action": sc.firsts[t]})
    return out


def main(argv=None) -> int:
    """Write the task-contrast rows of the given personas and scene seeds."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="JSONL file to write")
    ap.add_argument("--personas", default="", help="comma-separated personas (default: split 0's training ones)")
    ap.add_argument("--seeds", default="100-107", help="scene seeds, e.g. 100-107 (keep them off the evaluation's)")
    ap.add_argument("--only", default=None, help="keep the pairs that contain this task (e.g. the one a model misreads)")
    args = ap.parse_args(argv)

    from adaptbench.compiler import load_domain
    from adaptbench.llm.prompts import PromptBuilder
    from adaptbench.llm.task_probe import scene
    from adaptbench.training.student import training_personas

    domain = load_domain()
    personas = args.personas.split(",") if args.personas else list(training_personas(domain, "0"))
    unknown = sorted(set(personas) - set(domain.persona))
    if unknown:
        raise SystemExit(f"--personas: unknown {', '.join(unknown)}")
    if args.only and args.only not in domain.task:
        raise SystemExit(f"--only: unknown task {args.only} (choose from: {', '.join(domain.task)})")
    builder = PromptBuilder(domain, "planner")
    rows = [r for p in personas for s in seed_range(args.seeds)
            for r in task_pair_rows(scene(domain, p, s, list(domain.task), builder), args.only)]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("".join(json.dumps(r) + "\n" for r in rows))
    print(f"{len(rows) // 2} task pairs ({len(personas)} personas x {len(seed_range(args.seeds))} scenes) -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
