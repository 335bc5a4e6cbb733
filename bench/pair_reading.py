"""How much does a model read the few words that tell two prompts apart, distinction by distinction?

    python bench/pair_reading.py --rows runs/tasks/rows-unseen.jsonl --model runs/r24/K10/model-500 \\
        [--model runs/s29/A/model-200] [--only tea_eggs] [--json]

The rows are contrast pairs (two consecutive rows with one key: `bench/task_rows.py` for tasks,
`training.answer_rows` for answers), whose prompts differ only in the task's line or the user's answer, each
with its own next action. For one pair, with m_a = log p(a's action | a's prompt) - log p(b's action | a's
prompt) and m_b the same from b's side, the pair's **reading** is m_a + m_b: what the prompt's difference
moves the choice between the two actions, in nats. A model that ignores the difference scores 0 however
much it prefers one action (the preference cancels between the sides); the probes (`adapt probe tasks`,
`adapt probe answers`) instead ask whether the right action wins, which a shift of the prior alone can change.
Reading is grouped by distinction: the pair of tasks for task rows, the choice (`eggs.base`) for answer rows.

The twenty-ninth session found with it that training one distinction up can push another down (a see-saw),
which a probe's share hides. A measurement (docs/training.md), not a shipped tool.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

from cook_and_read import pair_examples  # bench/cook_and_read.py, beside this file


def distinction(a: dict, b: dict) -> str:
    """What tells a pair's two prompts apart: the two tasks ("cereal vs tea_eggs") for task rows, the choice
    (the key's second field, "eggs.base") for answer rows."""
    if a.get("at") == "task":
        return " vs ".join(sorted((a["task"], b["task"])))
    return a["key"].split("/")[1]


def row_pairs(rows: list) -> list:
    """The rows as (a, b) pairs; SystemExit when they are not in pairs of one key."""
    if len(rows) % 2:
        raise SystemExit(f"{len(rows)} rows: an odd count cannot be pairs")
    pairs = list(zip(rows[::2], rows[1::2], strict=True))
    for a, b in pairs:
        if a["key"] != b["key"]:
            raise SystemExit(f"rows out of pairs: {a['key']} is followed by {b['key']}")
    return pairs


def readings(model, tokenizer, pairs: list) -> list:
    """Each pair's (m_a, m_b): its two sides' margins for their own action over the other's (nats), from the
    prompts and actions as the contrast loss tokenizes them (`cook_and_read.pair_examples`)."""
    import torch

    from adaptbench.training.shared_prefix import prompt_action_logprobs

    out = []
    with torch.no_grad():
        for prompts, actions in pair_examples([row for pair in pairs for row in pair], tokenizer):
            lp = prompt_action_logprobs(model, prompts, actions)
            out.append((float(lp[0, 0] - lp[0, 1]), float(lp[1, 1] - lp[1, 0])))
    return out


def summary(pairs: list, margins: list) -> dict:
    """Per distinction and over all pairs: pairs, mean reading (m_a + m_b) and its standard error, and the
    share of pairs whose both sides prefer their own action."""
    groups: dict = {}
    for (a, b), m in zip(pairs, margins, strict=True):
        groups.setdefault(distinction(a, b), []).append(m)
    groups["all"] = list(margins)

    def stats(ms: list) -> dict:
        reads = [ma + mb for ma, mb in ms]
        se = statistics.stdev(reads) / len(reads) ** 0.5 if len(reads) > 1 else 0.0
        return {"pairs": len(ms), "reading": round(statistics.fmean(reads), 3), "se": round(se, 3),
                "both_sides": round(sum(ma > 0 and mb > 0 for ma, mb in ms) / len(ms), 3)}

    return {k: stats(v) for k, v in sorted(groups.items())}


def main(argv=None) -> int:
    """Print each model's reading per distinction (or JSON with --json)."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rows", required=True, nargs="+", help="contrast rows (JSONL, two a pair)")
    ap.add_argument("--model", required=True, action="append", help="a model (name or directory); repeatable")
    ap.add_argument("--only", default="", help="keep the distinctions whose name contains this (e.g. tea_eggs)")
    ap.add_argument("--threads", type=int, default=2, help="torch threads")
    ap.add_argument("--json", action="store_true", help="one JSON object: model -> distinction -> figures")
    args = ap.parse_args(argv)

    from adaptbench.training.answer_rows import read_rows

    missing = [p for p in args.rows if not Path(p).is_file()]
    if missing:
        raise SystemExit(f"no such rows file: {', '.join(missing)}")
    pairs = row_pairs(read_rows(args.rows))
    if args.only:
        pairs = [(a, b) for a, b in pairs if args.only in distinction(a, b)]
        if not pairs:
            raise SystemExit(f"no pair's distinction contains {args.only!r}")

    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    from adaptbench.llm.named import resolve_model

    torch.set_num_threads(args.threads)
    report = {}
    for name in args.model:
        path = resolve_model(name)
        tok = AutoTokenizer.from_pretrained(path)
        model = AutoModelForCausalLM.from_pretrained(path, dtype=torch.float32).eval()
        report[name] = summary(pairs, readings(model, tok, pairs))
    if args.json:
        print(json.dumps(report, indent=1))
        return 0
    for name, groups in report.items():
        print(f"{name}: reading (nats, both sides' margins summed; 0 = the difference is ignored)")
        for key, s in groups.items():
            print(f"  {key:34s} {s['reading']:+7.2f} ± {s['se']:.2f}  pairs {s['pairs']:4d}  "
                  f"both sides right {100 * s['both_sides']:5.1f}%")
    return 0


if __name__ == "__main__":
    sys.exit(main())
