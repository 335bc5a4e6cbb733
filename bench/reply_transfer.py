"""Does reading replies carry over to people the model never heard? Train on answer pairs, read held-out ones.

    python bench/reply_transfer.py --out runs/s30/smol --model models/smollm2 --train runs/s30/train.jsonl \\
        --held unseen=runs/s30/unseen.jsonl --held seen=runs/s30/seen.jsonl --held-limit 64 --steps 150 \\
        --train-top 10 --lr 3e-5 --threads 2

The twenty-ninth session found that a student trained from scratch reads the replies of the personas it trained
on (+6.4 nats a pair on their replies in a new scene) and hardly a new person's (+1.4, all of it one reply that
names the action's word), and argued that word knowledge is what it lacks. This measures that claim without the
cooking: a model (a pretrained one, or the student) is trained on the training personas' answer pairs with the
contrast loss (`cook_and_read.contrast_terms`: each side's prompt scores its own answer's action above the other
answer's; a model that ignores the answer cannot lower it), and every `--eval-every` updates each held-out set's
*reading* is measured (`pair_reading`: both sides' margins summed, nats; 0 = the reply is ignored). The held-out
sets name what they hold (`NAME=PATH`): the unseen personas' replies, and the training personas' replies in a
scene not trained on. Gain on the first over gain on the second is how much of what was learnt is reading
words rather than recognising people. Rows come from `training.answer_rows` (cut to their dialogue or whole).
Writes OUT/curve.jsonl, a line per evaluation. A measurement (docs/training.md), not a shipped tool.
"""

from __future__ import annotations

import argparse
import json
import random
import sys
import time
from pathlib import Path

from cook_and_read import batches, contrast_terms, pair_examples  # bench/, beside this file
from pair_reading import readings, row_pairs, summary


def held_sets(specs: list, limit: int) -> dict:
    """`NAME=PATH` held-out row files as {name: [(a, b) row pairs]}, each cut to at most `limit` pairs spread
    evenly over the file (a fixed subset, the same for every model)."""
    from adaptbench.training.answer_rows import read_rows

    out = {}
    for spec in specs:
        name, sep, path = spec.partition("=")
        if not sep or not name:
            raise SystemExit(f"--held {spec!r}: write NAME=PATH")
        if not Path(path).is_file():
            raise SystemExit(f"--held {name}: no such rows file: {path}")
        pairs = row_pairs(read_rows([path]))
        if limit and len(pairs) > limit:
            pairs = [pairs[i * len(pairs) // limit] for i in range(limit)]
        out[name] = pairs
    return out


def read_all(model, tok, held: dict, by_choice: bool = False) -> dict:
    """Each held-out set's reading over all its pairs (nats, standard error, share of pairs both ways); with
    `by_choice`, per choice too (`pair_reading.summary`'s groups)."""
    model.eval()
    out = {}
    for name, pairs in held.items():
        groups = summary(pairs, readings(model, tok, pairs))
        out[name] = groups if by_choice else groups["all"]
    model.train()
    return out


def freeze_below(model, top: int) -> int:
    """Leave only the top `top` decoder layers and the final norm trainable (a Llama-shaped model: `model.model.
    layers`, `model.model.norm`); returns the trainable parameter count. `top` 0 leaves every weight trainable."""
    if top:
        for p in model.parameters():
            p.requires_grad_(False)
        for part in [*model.model.layers[-top:], model.model.norm]:
            for p in part.parameters():
                p.requires_grad_(True)
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


def arguments(argv=None) -> argparse.Namespace:
    """The command line's settings."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="folder for curve.jsonl")
    ap.add_argument("--model", required=True, help="model to start from (a name or a directory)")
    ap.add_argument("--train", required=True, nargs="+", help="training answer rows (JSONL, two a pair)")
    ap.add_argument("--held", required=True, action="append", help="NAME=PATH held-out answer rows; repeatable")
    ap.add_argument("--held-limit", type=int, default=152, help="pairs read per held-out set (0: all)")
    ap.add_argument("--steps", type=int, default=150, help="updates")
    ap.add_argument("--pairs-per-update", type=int, default=2)
    ap.add_argument("--lr", type=float, default=2e-5)
    ap.add_argument("--beta", type=float, default=1.0, help="the contrast loss's scale on the log-prob margin")
    ap.add_argument("--train-top", type=int, default=0,
                    help="train only the top K decoder layers and the final norm (0: every weight); the layers below "
                         "keep the start model's word knowledge and cost no backward pass")
    ap.add_argument("--eval-every", type=int, default=50)
    ap.add_argument("--by-choice", action="store_true", help="record each choice's reading, not only all pairs'")
    ap.add_argument("--save", action="store_true", help="save the trained model to OUT/model at the end")
    ap.add_argument("--seed", type=int, default=0, help="pair order")
    ap.add_argument("--threads", type=int, default=1, help="torch threads")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    """Train on the training pairs; read the held-out sets before, every --eval-every updates, and at the end."""
    args = arguments(argv)
    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    from adaptbench.llm.named import resolve_model
    from adaptbench.training.answer_rows import read_rows

    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    curve = out / "curve.jsonl"
    if curve.is_file():
        raise SystemExit(f"{curve} exists: choose another --out")
    held = held_sets(args.held, args.held_limit)
    path = resolve_model(args.model)
    tok = AutoTokenizer.from_pretrained(path)
    model = AutoModelForCausalLM.from_pretrained(path, dtype=torch.float32)
    train = pair_examples(read_rows(args.train), tok)
    trainable = freeze_below(model, args.train_top)
    params = [p for p in model.parameters() if p.requires_grad]
    print(f"{trainable:,} trainable parameters; {len(train)} training pairs; held out: "
          + ", ".join(f"{k} {len(v)} pairs" for k, v in held.items()), flush=True)
    opt = torch.optim.AdamW(params, lr=args.lr, weight_decay=0.0)
    order = batches(len(train), args.pairs_per_update, random.Random(args.seed))
    t0 = time.perf_counter()

    def evaluate(step: int, loss: float) -> None:
        rec = {"step": step, "loss": round(loss, 4), "train_seconds": round(train_s, 1),
               "reading": read_all(model, tok, held, args.by_choice)}
        with curve.open("a") as f:
            f.write(json.dumps(rec) + "\n")
        print(json.dumps(rec), flush=True)

    train_s = 0.0
    evaluate(0, float("nan"))
    losses: list = []
    for step in range(1, args.steps + 1):
        t = time.perf_counter()
        opt.zero_grad()
        terms, _ = contrast_terms(model, [train[i] for i in next(order)], args.beta)
        loss = torch.stack(terms).mean()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(params, 1.0)
        opt.step()
        train_s += time.perf_counter() - t
        losses.append(float(loss.detach()))
        if step % 10 == 0:
            print(f"update {step}: loss {sum(losses[-10:]) / 10:.4f} ({time.perf_counter() - t0:.0f} s)", flush=True)
        if step % args.eval_every == 0 or step == args.steps:
            evaluate(step, sum(losses[-args.eval_every:]) / len(losses[-args.eval_every:]))
    if args.save:
        model.save_pretrained(out / "model")
        tok.save_pretrained(out / "model")
    return 0


if __name__ == "__main__":
    sys.exit(main())
