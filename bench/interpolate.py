r"""A model between two of the same shape: every weight (1 - t) * A + t * B.

    python bench/interpolate.py --a student --b runs/cook-read/model-200 --t 0.7 --out runs/interp-0.7
    python bench/interpolate.py --a student --b runs/cook-read/model-200 --t 1 --only 'self_attn' --out runs/attn
    python bench/interpolate.py --a runs/base --b runs/dpo/merged --t 1.5 --out runs/dpo-x1.5

A weight above 1 goes past B along the line from A (the fine-tuning's change scaled by t: task arithmetic).

`--only REGEX` mixes only the weights whose names match (e.g. `self_attn`, `layers\.[23]\.`); every other
weight stays A's (the fifteenth session's hybrids: one model's attention, the other's MLPs).

Used in the twelfth session (docs/training.md) to keep part of what a fine-tuned student learned (B: reading
the user's answer) while pulling its weights back toward the student it came from (A: cooking). The
tokenizer and config are B's. Not a shipped model: a measurement.
"""

from __future__ import annotations

import argparse
import sys


def main(argv=None) -> int:
    """Write the interpolated model and its tokenizer to --out."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--a", required=True, help="a model name or directory (weight 1 - t)")
    ap.add_argument("--b", required=True, help="a model directory of the same shape (weight t)")
    ap.add_argument("--t", type=float, required=True,
                    help="B's weight: 0 to 1 between the models, above 1 (up to 3) past B along A -> B (task arithmetic)")
    ap.add_argument("--only", default="", help="a regular expression: mix only the weights it finds in their names")
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    if not 0.0 <= args.t <= 3.0:
        ap.error(f"--t {args.t}: give a weight from 0 to 1 (between the models) or up to 3 (past B)")

    import re

    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    from adaptbench.llm.named import resolve_model

    a = AutoModelForCausalLM.from_pretrained(resolve_model(args.a), dtype=torch.float32).state_dict()
    model = AutoModelForCausalLM.from_pretrained(args.b, dtype=torch.float32)
    b = model.state_dict()
    if a.keys() != b.keys() or any(a[k].shape != b[k].shape for k in b):
        ap.error(f"{args.a} and {args.b} differ in shape: they cannot be interpolated")
    mixed = [k for k in b if re.search(args.only, k)]
    if not mixed:
        ap.error(f"--only {args.only!r} matches no weight name (e.g. {next(iter(b))})")
    model.load_state_dict({k: (1 - args.t) * a[k] + args.t * b[k] if k in mixed else a[k] for k in b})
    model.save_pretrained(args.out)
    AutoTokenizer.from_pretrained(args.b).save_pretrained(args.out)
    where = f" ({len(mixed)} of {len(b)} weights, the rest {args.a}'s)" if len(mixed) < len(b) else ""
    print(f"{args.out}: {1 - args.t:g} x {args.a} + {args.t:g} x {args.b}{where}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
