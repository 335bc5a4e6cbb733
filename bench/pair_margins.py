"""How far did DPO move a model toward the chosen side of its own training pairs?

    python bench/pair_margins.py --pairs runs/read-rdpo/pairs/pairs.jsonl --model runs/read-rdpo/base \\
        --model runs/read-rdpo/dpo/merged [--kind question] [--limit 250] [--after-answer]

For each pair of `--kind` (question or teacher rows of `adapt train data`), the summed log-probability of
the chosen and of the rejected completion after the pair's prompt, in the ids DPO trains on
(`trainers.rows.preference_row`), under each `--model`. Prints, per model, the mean chosen and rejected
log-probabilities, the mean margin (chosen - rejected), the share of pairs where the chosen side is the more
likely, and at the first token where the two part, the log-probability difference and the share where the
chosen token is the likelier: what a greedy student would now pick between the two. `--after-answer` keeps
the teacher rows a preference decided whose prompt holds an answered question (the rows that teach using an
answer, as `adapt train data --follow-questions` makes them). A measurement of why a
DPO model does or does not ask (docs/training.md), not a shipped tool.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys


def pair_logprobs(model, row) -> tuple:
    """(chosen, rejected, branch) for one `Encoded` preference row (`trainers.rows.preference_row`: the ids
    DPO trains on, the student's generated ids as the rejected side): the summed log-probabilities of the two
    completions after the prompt, and the log-probability difference of their first differing token at the
    point where they part: what greedy decoding decides between the two."""
    import torch

    k = next(i for i, (a, b) in enumerate(zip(row.chosen, row.rejected, strict=False)) if a != b)
    out = []
    for end in (row.chosen, row.rejected):
        ids = list(row.prompt) + list(end)
        with torch.no_grad():
            lp = torch.log_softmax(model(input_ids=torch.tensor([ids])).logits[0, len(row.prompt) - 1:-1].float(), -1)
        out.append((float(lp.gather(1, torch.tensor(end)[:, None]).sum()), lp[k]))
    (c, lp_k), (j, _) = out
    return c, j, float(lp_k[row.chosen[k]] - lp_k[row.rejected[k]])


def answered(row) -> bool:
    """Whether a row was decided by a preference and its prompt holds a question the user answered."""
    asked = any(m["role"] == "assistant" and m["content"].startswith("Action: Ask ") for m in row["prompt"])
    return bool(row.get("teacher_preferences")) and asked


def main(argv=None) -> int:
    """Score each model on the chosen and rejected sides of the pairs; print one line per model."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pairs", required=True, help="pairs.jsonl of `adapt train data`")
    ap.add_argument("--model", action="append", required=True, help="a model directory or name (repeat)")
    ap.add_argument("--kind", default="question", choices=("question", "teacher"))
    ap.add_argument("--limit", type=int, default=250, help="pairs scored at most (the first ones)")
    ap.add_argument("--after-answer", action="store_true",
                    help="only rows a preference decided whose prompt holds a question the user answered")
    args = ap.parse_args(argv)

    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    from adaptbench.llm.named import resolve_model
    from adaptbench.training.trainers.encode import Encoder, action_of
    from adaptbench.training.trainers.rows import preference_row

    torch.set_num_threads(1)
    with open(args.pairs) as f:
        rows = [r for r in map(json.loads, f) if r.get("kind") == args.kind and (not args.after_answer or answered(r))]
    rows = rows[:args.limit]
    for name in args.model:
        path = resolve_model(name)
        tok = AutoTokenizer.from_pretrained(path)
        model = AutoModelForCausalLM.from_pretrained(path, dtype=torch.float32).eval()
        enc = Encoder(tok)
        chosen, rejected, branch = [], [], []
        for r in rows:
            c, j, b = pair_logprobs(model, preference_row(enc, r, action_of(r["chosen"])))
            chosen.append(c)
            rejected.append(j)
            branch.append(b)
        margins = [c - j for c, j in zip(chosen, rejected, strict=True)]
        print(json.dumps({"model": name, "kind": args.kind, "after_answer": args.after_answer, "pairs": len(rows),
                          "chosen": round(statistics.mean(chosen), 2), "rejected": round(statistics.mean(rejected), 2),
                          "margin": round(statistics.mean(margins), 2),
                          "margin_median": round(statistics.median(margins), 2),
                          "chosen_more_likely": round(sum(m > 0 for m in margins) / len(margins), 3),
                          "branch_margin": round(statistics.mean(branch), 2),
                          "branch_median": round(statistics.median(branch), 2),
                          "chosen_branch_taken": round(sum(b > 0 for b in branch) / len(branch), 3)}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
