"""Does the tiny student fail to read the user's answer because of the long prompt, or at all?

    python bench/answer_context.py --out runs/answer-context [--steps 1500] [--eval-every 250]

The answer-use probe (`adapt probe answers`) has stayed at 50-57% for every student trained here. This
experiment separates two causes. It trains the shipped student on the answer rows (`training/answer_rows.py`,
split 0's training personas, scene seeds 100-101) with each prompt cut to its dialogue: the messages from
the user turn before the question onward (the task, the question, the reply and what followed it; no
system message, no layout). A row is then ~10x fewer tokens, so an update is ~10x cheaper. Every
`--eval-every` updates it scores the probe on split 0's unseen personas (scene seed 0) twice: on the cut
prompts (can this model read a reply at all, given a short context?) and on the full planner prompts (does
that reading carry over to the prompt the student acts on?). Writes OUT/curve.jsonl as it goes (one line
per evaluation) and prints a table at the end. Not a shipped model: a measurement (docs/training.md).
"""

from __future__ import annotations

import argparse
import json
import random
import sys
import time
from pathlib import Path

SPLIT0_UNSEEN = ("leila", "lisa", "mark", "samantha")


def row_loss(model, example: tuple):
    """Mean cross-entropy over the labelled (action and EOS) tokens of one `answer_examples` sequence."""
    import torch

    ids, labels = example
    return model(input_ids=torch.tensor([ids]), labels=torch.tensor([labels])).loss


def model_scorer(model, tokenizer, cut: bool):
    """A probe scorer (`llm.probe.Scorer`) over an in-process model: each action's summed log-probability (its
    tokens and EOS) after the rendered prompt, the prompt cut to its dialogue when `cut`."""
    import torch

    from adaptbench.llm.chat import render
    from adaptbench.llm.prompts import Prompt
    from adaptbench.training.answer_rows import dialogue

    def score(prompt, actions: tuple) -> tuple:
        if cut:
            prompt = Prompt(tuple(dialogue(list(prompt.messages))), prompt.prefix)
        p = tokenizer(render(tokenizer, prompt), add_special_tokens=False)["input_ids"]
        out = []
        for action in actions:
            a = tokenizer(action, add_special_tokens=False)["input_ids"] + [tokenizer.eos_token_id]
            with torch.no_grad():
                logp = model(input_ids=torch.tensor([p + a])).logits[0, len(p) - 1:-1].log_softmax(-1)
            out.append(float(logp[torch.arange(len(a)), torch.tensor(a)].sum()))
        return tuple(out)
    return score


def probe_share(model, tokenizer, pairs: list, cut: bool) -> dict:
    """The answer-use probe (`llm.probe.probe`) over `pairs`, on whole or cut prompts: its summary."""
    from adaptbench.llm.probe import probe

    r = probe(model_scorer(model, tokenizer, cut), pairs).summary()
    return {"share": round(r["share"], 4), "se": round(r["share_se"], 4), "pairs_both": round(r["pair_share"], 4),
            "shift": round(r["mean_shift"], 3)}


def seed_range(text: str) -> range:
    """`100-101` or `100` as a range of scene seeds."""
    lo, _, hi = text.partition("-")
    return range(int(lo), int(hi or lo) + 1)


def training_rows(domain, out: Path, seeds: str, said_seeds: str) -> list:
    """Split 0's training personas' answer rows in the scenes of `seeds` (OUT/rows.jsonl), and with
    `said_seeds` the templated-reply rows (OUT/said.jsonl); each file written once, read back after."""
    from adaptbench.training.answer_rows import answer_rows, read_rows, said_rows, write_rows
    from adaptbench.training.student import training_personas

    rows_path = out / "rows.jsonl"
    if not rows_path.is_file():
        write_rows(rows_path, answer_rows(domain, training_personas(domain, "0"), seed_range(seeds)))
    rows = read_rows([rows_path])
    if said_seeds:
        said_path = out / "said.jsonl"
        if not said_path.is_file():
            write_rows(said_path, said_rows(domain, seed_range(said_seeds)))
        rows += read_rows([said_path])
    return rows


def main(argv=None) -> int:
    """Train on cut answer rows; evaluate the probe on cut and full prompts as it goes."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="folder for curve.jsonl and the rows")
    ap.add_argument("--model", default="student", help="model to start from (a name or a directory)")
    ap.add_argument("--steps", type=int, default=1500, help="updates")
    ap.add_argument("--batch", type=int, default=8, help="rows an update (gradients summed one row at a time)")
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--eval-every", type=int, default=250)
    ap.add_argument("--pairs", type=int, default=100, help="probe pairs (unseen personas, scene seed 0)")
    ap.add_argument("--full-pairs", type=int, default=50, help="of those, scored on the full prompt too")
    ap.add_argument("--seeds", default="100-101", help="scene seeds of the training rows")
    ap.add_argument("--said-seeds", default="", help="scene seeds of templated-reply rows added (llm.probe.said_pairs)")
    ap.add_argument("--full", action="store_true", help="train on the full prompts instead (the control)")
    ap.add_argument("--personas", default=",".join(SPLIT0_UNSEEN), help="the probe's personas")
    ap.add_argument("--probe-seed", type=int, default=0, help="the probe's scene seed")
    args = ap.parse_args(argv)

    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    from adaptbench.compiler import load_domain
    from adaptbench.llm.named import resolve_model
    from adaptbench.llm.probe import build_pairs, spread
    from adaptbench.training.answer_rows import answer_examples
    torch.set_num_threads(1)
    torch.manual_seed(0)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    domain = load_domain()
    rows = training_rows(domain, out, args.seeds, args.said_seeds)
    pairs = spread(build_pairs(domain, personas=args.personas.split(","), seeds=(args.probe_seed,)), args.pairs)
    path = resolve_model(args.model)
    tok = AutoTokenizer.from_pretrained(path)
    model = AutoModelForCausalLM.from_pretrained(path, dtype=torch.float32)
    data = answer_examples(rows, tok, "full" if args.full else "dialogue")
    mean_len = sum(len(ids) for ids, _ in data) / len(data)
    print(f"{len(rows)} rows, {mean_len:.0f} tokens a row ({'full' if args.full else 'cut'}); "
          f"{len(pairs)} probe pairs", flush=True)
    opt = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=0.0)
    rng = random.Random(0)
    curve = out / "curve.jsonl"
    curve.write_text("")
    if not args.steps:  # a model probed only (--model DIR --steps 0)
        args.eval_every = 1
    t0 = time.perf_counter()

    def evaluate(step: int, loss: float) -> None:
        model.eval()
        cut = probe_share(model, tok, pairs, cut=True)
        full = probe_share(model, tok, pairs[:args.full_pairs], cut=False)
        rec = {"step": step, "loss": round(loss, 4), "seconds": round(time.perf_counter() - t0, 1),
               "probe_cut": cut, "probe_full": full}
        with curve.open("a") as f:
            f.write(json.dumps(rec) + "\n")
        print(json.dumps(rec), flush=True)
        model.train()

    evaluate(0, float("nan"))
    order: list = []
    losses: list = []
    for step in range(1, args.steps + 1):
        if len(order) < args.batch:
            order += rng.sample(range(len(data)), len(data))
        batch, order = [data[i] for i in order[:args.batch]], order[args.batch:]
        opt.zero_grad()
        total = 0.0
        for row in batch:  # one row at a time, gradients summed: no padding (a padded batch is ~3x slower)
            loss = row_loss(model, row) / len(batch)
            loss.backward()
            total += float(loss.detach())
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        losses.append(total)
        if step % args.eval_every == 0 or step == args.steps:
            evaluate(step, sum(losses[-50:]) / len(losses[-50:]))
    if args.steps:
        model.save_pretrained(out / "model")
        tok.save_pretrained(out / "model")
    return 0


if __name__ == "__main__":
    sys.exit(main())
