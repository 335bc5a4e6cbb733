"""Reflection-DPO on every weight of the student, held to its cooking by a KL anchor on its own episodes.

    python bench/anchored_rdpo.py --out runs/rd27/dpo --model runs/r24/K10/model-500 \\
        --data runs/rd26f/pairs --episodes runs/own/episodes.jsonl --method dpo [--steps 300] [--anchor-kl 10]

`adapt train dpo` trains a LoRA adapter (the paper's rank 4; rank 8 here) with TRL. On the ~1 M-parameter CPU
student, 60 such updates moved the decision that the twenty-sixth session's corrections ask for (the next
action after the user's answer) by 0.3 of the 6 nats it needs, and every longer or wider LoRA run cost the
dishes (docs/training.md). The twenty-fourth session held a full-weight student to its cooking while answer
pairs taught it to read, at lr 1e-3 over 500 updates, with a KL term: `bench/cook_and_read.py --anchor-kl`.
This experiment trains Reflection-DPO's own rows the same way. Each update takes `--rows-per-update` rows of
the method and `--episodes-per-update` whole episodes of the student's own training data, and its loss is

    mean(row terms + episodes' token losses) + W x KL(start model || model) over the episodes' action tokens

with the start model frozen, which is also DPO's reference. The row terms are the methods' (docs/training.md):
- `dpo` (Reflection-DPO, `sigmoid+sft` as the study's lanes): -log sigmoid(beta x ((log pi(c) - log ref(c)) -
  (log pi(r) - log ref(r)))) plus the chosen completion's mean token loss, on `adapt train data`'s question
  and teacher rows (`trainers.rows.dpo_rows`);
- `sft` (no DPO): the chosen completion's mean token loss on the same rows (`sft_rows`);
- `no-reflection`: the DPO terms with the teacher's action chosen at every step that reached the rule
  (`no_reflection_rows`).
Rows are encoded exactly as `adapt train dpo` encodes them (`trainers.encode.Encoder`), and `--mask-forced`
takes the bank's forced question tokens out of every term as `adapt train dpo --mask-forced` does. The model
is saved to OUT/model-STEP every `--save-every` updates (for `adapt rollout --model`), and OUT/curve.jsonl has
a line per ten updates. Not a shipped training method: a measurement (docs/training.md).
"""

from __future__ import annotations

import argparse
import json
import random
import sys
import time
from pathlib import Path

from cook_and_read import anchored_episode_terms, batches, training_episodes  # beside this file

METHODS = ("dpo", "sft", "no-reflection")


def method_rows(method: str, data: str, tok, mask: bool) -> list:
    """The method's rows from `adapt train data`'s output `data`, encoded as `adapt train` encodes them
    (with keep masks under `mask`)."""
    from adaptbench.compiler import load_domain
    from adaptbench.grammars.index import domain_questions
    from adaptbench.training.trainers import rows as R
    from adaptbench.training.trainers.encode import Encoder

    pairs, bad = R.read_pairs(data)
    enc = Encoder(tok)
    build = {"dpo": R.dpo_rows, "sft": R.sft_rows, "no-reflection": R.no_reflection_rows}[method]
    rows = build(pairs, enc)
    if not rows:
        raise SystemExit(f"--data {data}: no rows for {method}")
    if mask:
        rows, skipped = R.mask_forced_rows(rows, tok, domain_questions(load_domain()))
        print(f"--mask-forced: {skipped} forced question tokens carry no loss", flush=True)
    return rows


def completion_logprobs(model, prompt: tuple, completions: list) -> list:
    """Each completion's per-token log-probabilities after `prompt` (with gradients when `model` has them):
    the prompt runs once, each completion after its keys and values."""
    import torch

    from adaptbench.training.shared_prefix import _extend

    head = list(prompt[:-1])
    layers = _extend(model, torch, head, 0, (), logits_to_keep=1)[1]
    out = []
    for c in completions:
        logits = _extend(model, torch, head + [prompt[-1], *c], len(head), layers)[0]
        logp = logits[:-1].float().log_softmax(-1)
        out.append(logp[torch.arange(len(c)), torch.tensor(list(c), device=logp.device)])
    return out


def _keep(row, side: str):
    import torch

    mask = getattr(row, f"{side}_keep")
    n = len(getattr(row, side))
    return torch.ones(n) if mask is None else torch.tensor(mask, dtype=torch.float32)


def reference(anchor, row, cache: dict, index: int) -> tuple:
    """The frozen start model's summed (kept) log-probabilities of the row's chosen and rejected completions,
    computed once per row."""
    import torch

    if index not in cache:
        with torch.no_grad():
            lc, lr = completion_logprobs(anchor, row.prompt, [row.chosen, row.rejected])
        cache[index] = (float((lc * _keep(row, "chosen")).sum()), float((lr * _keep(row, "rejected")).sum()))
    return cache[index]


def row_terms(method: str, model, anchor, rows: list, idx: list, cache: dict, beta: float) -> tuple:
    """The rows' loss terms under `method`, and how many DPO rows put the chosen side ahead (0 for sft)."""
    import torch.nn.functional as F

    terms, right = [], 0
    for i in idx:
        row = rows[i]
        kc = _keep(row, "chosen")
        if method == "sft":
            (lc,) = completion_logprobs(model, row.prompt, [row.chosen])
            terms.append(-(lc * kc).sum() / kc.sum().clamp(min=1))
            continue
        lc, lr = completion_logprobs(model, row.prompt, [row.chosen, row.rejected])
        sc, sr = (lc * kc).sum(), (lr * _keep(row, "rejected")).sum()
        rc, rr = reference(anchor, row, cache, i)
        margin = (sc - rc) - (sr - rr)
        right += int(float(margin.detach()) > 0)
        term = -F.logsigmoid(beta * margin)
        if method == "dpo":
            term = term - sc / kc.sum().clamp(min=1)  # sigmoid+sft: the chosen side's mean token loss
        terms.append(term)
    return terms, right


def main(argv=None) -> int:
    """Train one method's rows on full weights beside anchored episodes; save as it goes."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="folder for curve.jsonl and the saved models")
    ap.add_argument("--model", required=True, help="the base student (a name or a directory); also the reference")
    ap.add_argument("--data", required=True, help="`adapt train data` output (a directory with pairs.jsonl)")
    ap.add_argument("--method", choices=METHODS, default="dpo")
    ap.add_argument("--episodes", required=True, nargs="+", help="the base's own training episodes (JSONL records)")
    ap.add_argument("--steps", type=int, default=300, help="updates")
    ap.add_argument("--rows-per-update", type=int, default=4)
    ap.add_argument("--episodes-per-update", type=int, default=2)
    ap.add_argument("--anchor-kl", type=float, default=10.0, help="weight of KL(start || model) on the episodes")
    ap.add_argument("--beta", type=float, default=0.1, help="DPO beta (adapt train dpo's default)")
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--mask-forced", action="store_true", help="no loss on the bank's forced question tokens")
    ap.add_argument("--save-every", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0, help="data order")
    ap.add_argument("--threads", type=int, default=1, help="torch threads (default 1: the run beside another job)")
    args = ap.parse_args(argv)

    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    from adaptbench.compiler import load_domain
    from adaptbench.llm.named import resolve_model

    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    out = Path(args.out)
    curve = out / "curve.jsonl"
    if curve.is_file():
        raise SystemExit(f"{curve} exists: choose another --out")
    out.mkdir(parents=True, exist_ok=True)
    path = resolve_model(args.model)
    tok = AutoTokenizer.from_pretrained(path)
    model = AutoModelForCausalLM.from_pretrained(path, dtype=torch.float32)
    anchor = AutoModelForCausalLM.from_pretrained(path, dtype=torch.float32).eval().requires_grad_(False)
    rows = method_rows(args.method, args.data, tok, args.mask_forced)
    episodes = training_episodes(load_domain(), tok, args.episodes, args.mask_forced)
    print(f"{args.method}: {len(rows)} rows, {len(episodes)} episodes; {args.steps} updates of "
          f"{args.rows_per_update} rows + {args.episodes_per_update} episodes, lr {args.lr}, KL x {args.anchor_kl}",
          flush=True)
    opt = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=0.0)
    rng = random.Random(args.seed)
    row_batches, ep_batches = batches(len(rows), args.rows_per_update, rng), batches(len(episodes),
                                                                                    args.episodes_per_update, rng)
    cache: dict = {}
    seen: list = []
    t0 = time.perf_counter()
    for step in range(1, args.steps + 1):
        opt.zero_grad()
        terms, right = row_terms(args.method, model, anchor, rows, next(row_batches), cache, args.beta)
        ce, kls = anchored_episode_terms(model, anchor, [episodes[i] for i in next(ep_batches)])
        kl = torch.stack(kls).mean()
        loss = torch.stack(terms + ce).mean() + args.anchor_kl * kl
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        seen.append((float(loss.detach()), float(kl.detach()), right, float(torch.stack(ce).mean().detach())))
        if step % 10 == 0:
            last = seen[-10:]
            rec = {"step": step, "loss": round(sum(x[0] for x in last) / 10, 4),
                   "kl": round(sum(x[1] for x in last) / 10, 5),
                   "episode_loss": round(sum(x[3] for x in last) / 10, 4),
                   "chosen_ahead": None if args.method == "sft" else sum(x[2] for x in last) / (10 * args.rows_per_update),
                   "seconds": round(time.perf_counter() - t0, 1)}
            with curve.open("a") as f:
                f.write(json.dumps(rec) + "\n")
            print(json.dumps(rec), flush=True)
        if step % args.save_every == 0 or step == args.steps:
            model.save_pretrained(out / f"model-{step}")
            tok.save_pretrained(out / f"model-{step}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
