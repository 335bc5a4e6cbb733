"""Reflection-DPO on every weight of the student, held to its cooking by a KL anchor on its own episodes.

    python bench/anchored_rdpo.py --out runs/rd27/dpo --model runs/r24/K10/model-500 \\
        --data runs/rd26f/pairs [runs/rd28/pairs ...] --episodes runs/own/episodes.jsonl --method dpo [--steps 300] [--anchor-kl 10]

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
a line per ten updates; the same command run again resumes after the last saved model (its optimizer state
saved with it, the data order replayed), and Ctrl-C stops it saying where. Not a shipped training method: a
measurement (docs/training.md).
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


def method_rows(method: str, data: list, tok, mask: bool) -> list:
    """The method's rows from `adapt train data`'s outputs `data` (one or several folders, e.g. different
    scene seeds), encoded as `adapt train` encodes them (with keep masks under `mask`)."""
    from adaptbench.compiler import load_domain
    from adaptbench.errors import AdaptError
    from adaptbench.grammars.index import domain_questions
    from adaptbench.training.trainers import rows as R
    from adaptbench.training.trainers.encode import Encoder

    try:
        pairs = [row for folder in data for row in R.read_pairs(folder)[0]]
    except AdaptError as exc:  # no pairs.jsonl, an unfinished build, a bad row: the message names it
        raise SystemExit(str(exc)) from None
    enc = Encoder(tok)
    build = {"dpo": R.dpo_rows, "sft": R.sft_rows, "no-reflection": R.no_reflection_rows}[method]
    rows = build(pairs, enc)
    if not rows:
        raise SystemExit(f"--data {' '.join(data)}: no rows for {method}")
    if mask:
        rows, skipped = R.mask_forced_rows(rows, tok, domain_questions(load_domain()))
        print(f"--mask-forced: {skipped} forced question tokens carry no loss", flush=True)
    return rows


def completion_logprobs(model, prompt: tuple, completions: list) -> list:
    """Each completion's per-token log-probabilities after `prompt` (`shared_prefix.completion_token_logprobs`)."""
    from adaptbench.training.shared_prefix import completion_token_logprobs

    return completion_token_logprobs(model, prompt, completions)


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


SETTINGS = ("model", "data", "method", "episodes", "rows_per_update", "episodes_per_update", "anchor_kl", "beta", "lr",
            "mask_forced", "seed")  # what a resumed run must share with the first


def parse(argv=None):
    """The command line."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="folder for curve.jsonl and the saved models; an existing one resumes")
    ap.add_argument("--model", required=True, help="the base student (a name or a directory); also the reference")
    ap.add_argument("--data", required=True, nargs="+",
                    help="`adapt train data` outputs (directories with pairs.jsonl; several are read in order)")
    ap.add_argument("--method", choices=METHODS, default="dpo")
    ap.add_argument("--episodes", required=True, nargs="+", help="the base's own training episodes (JSONL records)")
    ap.add_argument("--steps", type=int, default=300, help="updates")
    ap.add_argument("--rows-per-update", type=int, default=4)
    ap.add_argument("--episodes-per-update", type=int, default=2)
    ap.add_argument("--anchor-kl", type=float, default=10.0, help="weight of KL(start || model) on the episodes")
    ap.add_argument("--beta", type=float, default=0.1, help="DPO beta (adapt train dpo's default)")
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--mask-forced", action="store_true", help="no loss on the bank's forced question tokens")
    ap.add_argument("--save-every", type=int, default=100, help="updates between saved models (and resume points)")
    ap.add_argument("--seed", type=int, default=0, help="data order")
    ap.add_argument("--threads", type=int, default=1, help="torch threads (default 1: the run beside another job)")
    return ap.parse_args(argv)


def resume_point(out: Path, args) -> int:
    """The last saved update of a run in `out` (0 for a new one), its curve cut back to it; SystemExit when
    `out` holds a run with other settings."""
    settings = {k: getattr(args, k) for k in SETTINGS}
    recorded = out / "settings.json"
    if recorded.is_file():
        old = json.loads(recorded.read_text())
        changed = sorted(k for k in SETTINGS if old.get(k) != settings[k])
        if changed:
            raise SystemExit(f"{out} holds a run with other settings ({', '.join(changed)}): choose another --out")
    elif (out / "curve.jsonl").is_file():
        raise SystemExit(f"{out} holds a curve but no settings.json: choose another --out")
    out.mkdir(parents=True, exist_ok=True)
    recorded.write_text(json.dumps(settings, indent=1) + "\n")
    at = max(saved_steps(out), default=0)
    curve = out / "curve.jsonl"
    if curve.is_file():
        lines = [line for line in curve.read_text().splitlines() if json.loads(line)["step"] <= at]
        curve.write_text("".join(line + "\n" for line in lines))
    return at


def saved_steps(out: Path) -> list:
    """The updates whose model and optimizer state are saved whole in `out` (a `.partial` one is not)."""
    return [int(d.name[len("model-"):]) for d in out.glob("model-*")
            if d.name[len("model-"):].isdigit() and (d / "optimizer.pt").is_file()]


def save(out: Path, step: int, model, tok, opt) -> None:
    """The model (for `adapt rollout --model`) and the optimizer's state (to resume) in OUT/model-STEP, written
    beside and then put in place."""
    import shutil

    import torch

    final, tmp = out / f"model-{step}", out / f"model-{step}.partial"
    shutil.rmtree(tmp, ignore_errors=True)
    model.save_pretrained(tmp)
    tok.save_pretrained(tmp)
    torch.save(opt.state_dict(), tmp / "optimizer.pt")
    shutil.rmtree(final, ignore_errors=True)
    tmp.rename(final)


def curve_line(step: int, seen: list, method: str, per_update: int, seconds: float) -> dict:
    """The mean figures of the last ten updates."""
    last = seen[-10:]
    n = len(last)
    return {"step": step, "loss": round(sum(x[0] for x in last) / n, 4), "kl": round(sum(x[1] for x in last) / n, 5),
            "episode_loss": round(sum(x[3] for x in last) / n, 4),
            "chosen_ahead": None if method == "sft" else sum(x[2] for x in last) / (n * per_update),
            "seconds": round(seconds, 1)}


def update(args, model, anchor, opt, rows, episodes, row_idx, ep_idx, cache) -> tuple:
    """One optimizer step; returns (loss, KL, DPO rows with the chosen side ahead, episodes' token loss)."""
    import torch

    opt.zero_grad()
    terms, right = row_terms(args.method, model, anchor, rows, row_idx, cache, args.beta)
    ce, kls = anchored_episode_terms(model, anchor, [episodes[i] for i in ep_idx])
    kl = torch.stack(kls).mean()
    loss = torch.stack(terms + ce).mean() + args.anchor_kl * kl
    loss.backward()
    torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
    opt.step()
    return float(loss.detach()), float(kl.detach()), right, float(torch.stack(ce).mean().detach())


def main(argv=None) -> int:
    """Train one method's rows on full weights beside anchored episodes; save as it goes, resume from the last
    saved model, stop at Ctrl-C saying where."""
    args = parse(argv)

    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    from adaptbench.compiler import load_domain
    from adaptbench.llm.named import resolve_model

    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    out = Path(args.out)
    at = resume_point(out, args)
    path = resolve_model(args.model)
    tok = AutoTokenizer.from_pretrained(path)
    rows = method_rows(args.method, args.data, tok, args.mask_forced)  # bad data stops the run before the models load
    model = AutoModelForCausalLM.from_pretrained(out / f"model-{at}" if at else path, dtype=torch.float32)
    anchor = AutoModelForCausalLM.from_pretrained(path, dtype=torch.float32).eval().requires_grad_(False)
    episodes = training_episodes(load_domain(), tok, args.episodes, args.mask_forced)
    print(f"{args.method}: {len(rows)} rows, {len(episodes)} episodes; {args.steps} updates of "
          f"{args.rows_per_update} rows + {args.episodes_per_update} episodes, lr {args.lr}, KL x {args.anchor_kl}"
          + (f"; resuming after update {at}" if at else ""), flush=True)
    opt = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=0.0)
    if at:
        opt.load_state_dict(torch.load(out / f"model-{at}" / "optimizer.pt"))
    rng = random.Random(args.seed)
    row_batches = batches(len(rows), args.rows_per_update, rng)
    ep_batches = batches(len(episodes), args.episodes_per_update, rng)
    for _ in range(at):  # the data order the first run went through
        next(row_batches), next(ep_batches)
    cache: dict = {}
    seen: list = []
    t0 = time.perf_counter()
    step = at
    try:
        for step in range(at + 1, args.steps + 1):
            seen.append(update(args, model, anchor, opt, rows, episodes, next(row_batches), next(ep_batches), cache))
            if step % 10 == 0:
                rec = curve_line(step, seen, args.method, args.rows_per_update, time.perf_counter() - t0)
                with (out / "curve.jsonl").open("a") as f:
                    f.write(json.dumps(rec) + "\n")
                print(json.dumps(rec), flush=True)
            if step % args.save_every == 0 or step == args.steps:
                save(out, step, model, tok, opt)
    except KeyboardInterrupt:
        last = max(saved_steps(out), default=0)
        print(f"stopped during update {step}; the same command resumes after update {last}", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
