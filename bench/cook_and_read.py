"""Can one student both cook and read the user's answer, on the whole planner prompt?

    python bench/cook_and_read.py --out runs/cook-read --model runs/ac-cut/model \\
        --episodes runs/mix/data/oracle.jsonl --rows runs/ac-cut/rows.jsonl [--steps 400] [--eval-every 100]

The eleventh session found that a student trained on answer rows alone learns to read replies but forgets
how to cook, and one trained with the oracle's episodes as a tenth of its sequences keeps cooking but sees
too few rows to read. This experiment gives each update a fixed mix: `--episodes-per-update` of the oracle's
whole episodes (packed, the loss on every action) and `--rows-per-update` answer rows, all on the whole
planner prompt. The sequences of an update share their ~1,230-token system message, which
`training.shared_prefix` runs once (the loss and gradients are those of running each whole; 1.1-1.2x
faster for eight rows on a quiet core: bench/bench_shared_prefix.py). Every `--eval-every` updates it scores
the answer-use probe on the whole prompt (split 0's unseen personas, scene seed 0), appends a line to
OUT/curve.jsonl and saves the model to OUT/model-STEP (for `adapt rollout --model` on the unseen personas,
which measures the cooking). Not a shipped model: a measurement (docs/training.md).

`--mask-forced` (the twenty-second session) drops the loss on the question tokens a `bank` grammar forces
(`training.forced_tokens`), where a student that never saw a question puts nearly all of its loss.

`--anchor-kl W` (the twenty-fourth session) adds W x KL(start model || model) over the episodes' action
tokens, the start model frozen (`anchored_episode_terms`): the answer pairs may then move only what leaves
the cook's own choices where they were.

`--row-loss contrast` (the twentieth session) trains the rows as pairs instead: each side's prompt scores its
own answer's action against the other answer's, -log sigmoid(beta x margin) (`contrast_terms`). A model that
ignores the answer cannot lower it, and it leaves the actions' likelihoods to the episodes, where the
likelihood of the rows (`sft`) pulls the student toward the rows' prompts. `--rows-per-update` still counts
rows (two a pair); the prompts' shared opening runs once (`training.shared_prefix.prompt_action_logprobs`).

`--pair-sampling hard` (the twenty-ninth session) draws the contrast pairs in proportion to their last known loss
(`HardPairs`) instead of each once per pass: among thousands of pairs the model already tells apart, the few it
does not are otherwise a sliver of the updates, and a pair pushed back by training on its neighbour is drawn again.
"""

from __future__ import annotations

import argparse
import json
import random
import sys
import time
from pathlib import Path

from answer_context import SPLIT0_UNSEEN, probe_share  # bench/answer_context.py, beside this file


def batches(n_items: int, per_update: int, rng: random.Random):
    """Endless batches of `per_update` indices into `n_items`, each index once per shuffled pass."""
    order: list = []
    while True:
        if len(order) < per_update:
            order += rng.sample(range(n_items), n_items)
        yield order[:per_update]
        order = order[per_update:]


class HardPairs:
    """`--pair-sampling hard`: each update draws its pairs with chance in proportion to each pair's last known
    contrast loss (plus `floor` x the mean, so that no pair is never drawn again), instead of each pair once per
    shuffled pass. The losses are scored once at the start (`pair_losses`), updated for the pairs an update trained
    on, and re-scored for `rescore` other pairs an update (without gradients), so that a pair the training
    pushes back (the twenty-ninth session's see-saw: one task pair learnt, its neighbour lost) is drawn again."""

    def __init__(self, losses: list, rng: random.Random, floor: float = 0.05, rescore: int = 4):
        self.losses, self.rng, self.floor, self.rescore = list(losses), rng, floor, rescore

    def draw(self, k: int) -> list:
        """k distinct pair indices, each drawn in proportion to its loss (+ the floor)."""
        base = self.floor * sum(self.losses) / len(self.losses)
        weights = [loss + base + 1e-12 for loss in self.losses]
        chosen: list = []
        while len(chosen) < min(k, len(weights)):
            i = self.rng.choices(range(len(weights)), weights)[0]
            if i not in chosen:
                chosen.append(i)
        return chosen

    def update(self, indices: list, terms: list) -> None:
        """The trained pairs' losses: each pair's two side terms (in `indices` order), summed."""
        for n, i in enumerate(indices):
            self.losses[i] = float(terms[2 * n].detach()) + float(terms[2 * n + 1].detach())

    def others(self, exclude: list) -> list:
        """`rescore` pair indices to score again without gradients (none of `exclude`)."""
        pool = [i for i in range(len(self.losses)) if i not in exclude]
        return self.rng.sample(pool, min(self.rescore, len(pool)))


def pair_losses(model, pairs: list, beta: float) -> list:
    """Each pair's contrast loss (its two side terms summed), without gradients."""
    import torch

    with torch.no_grad():
        terms, _ = contrast_terms(model, pairs, beta)
    return [float(terms[2 * n]) + float(terms[2 * n + 1]) for n in range(len(pairs))]


def episode_losses(model, episodes: list) -> list:
    """Each packed episode's mean token loss, run whole."""
    import torch

    return [model(input_ids=torch.tensor([ids]), labels=torch.tensor([labels])).loss for ids, labels in episodes]


def anchored_episode_terms(model, anchor, episodes: list) -> tuple:
    """Each packed episode's mean token loss, and its mean KL(anchor || model) over the labelled (action)
    tokens: how far the model's next-token distribution has moved from the frozen start model's where the
    student acts. The anchor runs without gradients."""
    import torch
    import torch.nn.functional as F

    losses, kls = [], []
    for ids, labels in episodes:
        x, y = torch.tensor([ids]), torch.tensor([labels])
        out = model(input_ids=x, labels=y)
        with torch.no_grad():
            ref = anchor(input_ids=x).logits
        acts = y[0, 1:] != -100  # logits at t predict token t + 1
        p_log = F.log_softmax(out.logits[0, :-1][acts], dim=-1)
        ref_log = F.log_softmax(ref[0, :-1][acts], dim=-1)
        kls.append(F.kl_div(p_log, ref_log, log_target=True, reduction="batchmean"))
        losses.append(out.loss)
    return losses, kls


def contrast_update_loss(model, anchor, weight: float, episodes: list, pairs: list, beta: float,
                         sampler: HardPairs | None = None, indices: tuple = ()) -> tuple:
    """One update's loss under `--row-loss contrast`: the mean of the episodes' token losses and the pairs'
    contrast terms, plus `weight` x the episodes' mean KL from `anchor` when there is one. Returns (the loss,
    the sides that prefer their own action, the sides, the KL as a float: 0.0 without an anchor). With a
    `sampler`, the trained pairs' (`indices`) losses are handed to it."""
    import torch

    terms, right = contrast_terms(model, pairs, beta)
    if sampler is not None:
        sampler.update(list(indices), terms)
    if anchor is None:
        return torch.stack(episode_losses(model, episodes) + terms).mean(), right, len(terms), 0.0
    ce, kls = anchored_episode_terms(model, anchor, episodes)
    kl = torch.stack(kls).mean()
    return torch.stack(ce + terms).mean() + weight * kl, right, len(terms), float(kl.detach())


def frozen_anchor(path, args):
    """The start model, frozen, for `--anchor-kl` (which needs the contrast loss and episodes to anchor on)."""
    import torch
    from transformers import AutoModelForCausalLM

    if args.row_loss != "contrast" or not args.episodes_per_update:
        raise SystemExit("--anchor-kl takes --row-loss contrast and at least one episode an update")
    return AutoModelForCausalLM.from_pretrained(path, dtype=torch.float32).eval().requires_grad_(False)


def update_loss(model, episodes: list, rows: list):
    """The mean of the sequences' mean token losses (each sequence weighs the same). The answer rows run
    after their shared system message (`training.shared_prefix`: 1.1-1.2x faster for whole-prompt rows); the
    episodes run whole, since a long remainder attends faster with the causal kernel than after a cache."""
    import torch

    from adaptbench.training.shared_prefix import shared_prefix_loss

    parts = episode_losses(model, episodes)
    if rows:
        parts += [shared_prefix_loss(model, rows)] * len(rows)
    return torch.stack(parts).mean()


def pair_examples(rows: list, tokenizer) -> list:
    """The answer rows as pairs for the answer-contrast loss: for each probe pair (two consecutive rows with
    one key), its two prompts' token ids and its two actions' (each with EOS)."""
    from adaptbench.llm.chat import render
    from adaptbench.llm.prompts import Prompt

    if len(rows) % 2:
        raise SystemExit(f"{len(rows)} answer rows: an odd count cannot be pairs")
    out = []
    for a, b in zip(rows[::2], rows[1::2], strict=True):
        if a["key"] != b["key"]:
            raise SystemExit(f"answer rows out of pairs: {a['key']} is followed by {b['key']}")
        prompts = [tokenizer(render(tokenizer, Prompt(tuple(r["messages"]), r.get("prefix", ""))),
                             add_special_tokens=False)["input_ids"] for r in (a, b)]
        actions = [tokenizer(r["action"], add_special_tokens=False)["input_ids"] + [tokenizer.eos_token_id]
                   for r in (a, b)]
        out.append((prompts, actions))
    return out


def contrast_terms(model, pairs: list, beta: float):
    """The answer-contrast loss of each side of each pair: -log sigmoid(beta x (log p(own action | prompt) -
    log p(the other answer's action | prompt))). Only acting on the answer lowers it: a model that ignores
    the answer gains on one side what it loses on the other. Returns (the terms, how many sides prefer
    their own action)."""
    import torch
    import torch.nn.functional as F

    from adaptbench.training.shared_prefix import prompt_action_logprobs

    terms, right = [], 0
    for prompts, actions in pairs:
        lp = prompt_action_logprobs(model, prompts, actions)
        margins = torch.stack([lp[0, 0] - lp[0, 1], lp[1, 1] - lp[1, 0]])
        right += int((margins.detach() > 0).sum())
        terms += list(-F.logsigmoid(beta * margins))
    return terms, right


def episode_examples(domain, tok, paths: list) -> list:
    """The oracle's episodes as packed whole-prompt sequences (`training.pretrain.examples`)."""
    from adaptbench.training.pretrain import examples, read_records

    data, skipped = examples(domain, read_records(paths), tok, None)
    if skipped:
        print(f"{skipped} episodes skipped (not reproducible with this spec)", flush=True)
    return data


def training_episodes(domain, tok, paths: list, mask: bool) -> list:
    """The episodes' packed sequences; with `mask`, a bank question's forced tokens carry no loss."""
    episodes = episode_examples(domain, tok, paths)
    if not mask:
        return episodes
    from adaptbench.grammars.index import domain_questions
    from adaptbench.training.forced_tokens import mask_examples

    episodes, removed = mask_examples(episodes, tok, domain_questions(domain))
    print(f"--mask-forced: {removed} forced question tokens carry no loss", flush=True)
    return episodes


def arguments(argv=None) -> argparse.Namespace:
    """The command line's settings."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="folder for curve.jsonl and the saved models")
    ap.add_argument("--model", default="student", help="model to start from (a name or a directory)")
    ap.add_argument("--episodes", required=True, nargs="+", help="oracle episode records (JSONL)")
    ap.add_argument("--rows", required=True, nargs="+", help="answer rows (JSONL, training/answer_rows.py)")
    ap.add_argument("--steps", type=int, default=400, help="updates")
    ap.add_argument("--episodes-per-update", type=int, default=4)
    ap.add_argument("--rows-per-update", type=int, default=4)
    ap.add_argument("--rows-context", choices=("full", "dialogue"), default="full",
                    help="answer rows on the whole prompt (default) or cut to their dialogue (answer_rows.CONTEXTS)")
    ap.add_argument("--row-loss", choices=("sft", "contrast"), default="sft",
                    help="sft: the answer's action's likelihood on each row (default); contrast: each side's own "
                         "action against the other answer's (contrast_terms), which only reading lowers")
    ap.add_argument("--mask-forced", action="store_true",
                    help="no loss on the tokens of a bank question that the bank forces (training.forced_tokens): "
                         "the loss stays on Ask itself and where two questions part")
    ap.add_argument("--beta", type=float, default=1.0, help="the contrast loss's scale on the log-prob margin")
    ap.add_argument("--pair-sampling", choices=("uniform", "hard"), default="uniform",
                    help="contrast pairs each once per shuffled pass (default), or drawn in proportion to their last "
                         "known loss (HardPairs: scored once at the start, then re-scored as it goes)")
    ap.add_argument("--anchor-kl", type=float, default=0.0,
                    help="weight of KL(start model || model) on the episodes' action tokens (0: none)")
    ap.add_argument("--anchor-model", default="",
                    help="the model --anchor-kl holds to (default --model; give the first start to continue a run)")
    ap.add_argument("--lr", type=float, default=5e-4)
    ap.add_argument("--eval-every", type=int, default=100)
    ap.add_argument("--pairs", type=int, default=60, help="probe pairs (unseen personas, scene seed 0), whole prompts")
    ap.add_argument("--personas", default=",".join(SPLIT0_UNSEEN), help="the probe's personas")
    ap.add_argument("--seed", type=int, default=0, help="data order")
    ap.add_argument("--threads", type=int, default=1, help="torch threads (default 1: the run beside another job)")
    return ap.parse_args(argv)


def make_sampler(args, model, rows: list, rng: random.Random) -> HardPairs | None:
    """`--pair-sampling hard`'s sampler, every pair scored once (None for uniform sampling)."""
    if args.pair_sampling != "hard":
        return None
    if args.row_loss != "contrast":
        raise SystemExit("--pair-sampling hard takes --row-loss contrast")
    print(f"scoring {len(rows)} pairs for --pair-sampling hard", flush=True)
    return HardPairs(pair_losses(model, rows, args.beta), rng)


def pick_rows(sampler: HardPairs | None, row_batches, per_update: int, model, rows: list, beta: float) -> list:
    """The next update's row (or pair) indices: the next shuffled batch, or the sampler's draw, after it has
    re-scored a few other pairs."""
    if sampler is None:
        return next(row_batches)
    picked = sampler.draw(per_update)
    others = sampler.others(picked)
    for i, loss_i in zip(others, pair_losses(model, [rows[i] for i in others], beta), strict=True):
        sampler.losses[i] = loss_i
    return picked


def main(argv=None) -> int:
    """Train on a fixed mix of whole episodes and answer rows; probe and save as it goes."""
    args = arguments(argv)

    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    from adaptbench.compiler import load_domain
    from adaptbench.llm.named import resolve_model
    from adaptbench.llm.probe import build_pairs, spread
    from adaptbench.training.answer_rows import answer_examples, read_rows
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    domain = load_domain()
    path = resolve_model(args.model)
    tok = AutoTokenizer.from_pretrained(path)
    model = AutoModelForCausalLM.from_pretrained(path, dtype=torch.float32)
    episodes = training_episodes(domain, tok, args.episodes, args.mask_forced)
    if args.row_loss == "contrast":
        if args.rows_context != "full" or args.rows_per_update % 2:
            raise SystemExit("--row-loss contrast takes whole-prompt rows, an even --rows-per-update (two a pair)")
        rows = pair_examples(read_rows(args.rows), tok)
        per_update = args.rows_per_update // 2
    else:
        rows = answer_examples(read_rows(args.rows), tok, args.rows_context)
        per_update = args.rows_per_update
    pairs = spread(build_pairs(domain, personas=args.personas.split(","), seeds=(0,)), args.pairs)
    print(f"{len(episodes)} episodes ({sum(len(i) for i, _ in episodes) / len(episodes):.0f} tokens each), "
          f"{len(rows)} answer {'pairs' if args.row_loss == 'contrast' else 'rows'}; {len(pairs)} probe pairs",
          flush=True)
    anchor = frozen_anchor(resolve_model(args.anchor_model) if args.anchor_model else path, args) \
        if args.anchor_kl else None
    opt = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=0.0)
    rng = random.Random(args.seed)
    ep_batches = batches(len(episodes), args.episodes_per_update, rng)
    row_batches = batches(len(rows), per_update, rng)
    sampler = make_sampler(args, model, rows, rng)
    curve = out / "curve.jsonl"
    done = [json.loads(line)["step"] for line in curve.read_text().splitlines()] if curve.is_file() else []
    if done:
        raise SystemExit(f"{curve} exists (steps {done}): choose another --out")
    t0 = time.perf_counter()

    def evaluate(step: int, loss: float) -> None:
        model.eval()
        rec = {"step": step, "loss": round(loss, 4), "seconds": round(time.perf_counter() - t0, 1),
               "probe_full": probe_share(model, tok, pairs, cut=False)}
        with curve.open("a") as f:
            f.write(json.dumps(rec) + "\n")
        print(json.dumps(rec), flush=True)
        if step:
            model.save_pretrained(out / f"model-{step}")
            tok.save_pretrained(out / f"model-{step}")
        model.train()

    evaluate(0, float("nan"))
    losses: list = []
    sides = right = 0
    kl_seen: list = []
    for step in range(1, args.steps + 1):
        picked = pick_rows(sampler, row_batches, per_update, model, rows, args.beta)
        eps, batch_rows = [episodes[i] for i in next(ep_batches)], [rows[i] for i in picked]
        opt.zero_grad()
        if args.row_loss == "contrast":
            loss, ok, n, kl = contrast_update_loss(model, anchor, args.anchor_kl, eps, batch_rows, args.beta,
                                                   sampler, tuple(picked))
            sides, right = sides + n, right + ok
            kl_seen += [kl] if anchor is not None else []
        else:
            loss = update_loss(model, eps, batch_rows)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        losses.append(float(loss.detach()))
        if step % 10 == 0:
            acc = f", {right}/{sides} sides prefer their own action" if sides else ""
            acc += f", KL to the start {sum(kl_seen[-10:]) / 10:.4f}" if kl_seen else ""
            print(f"update {step}: loss {sum(losses[-10:]) / 10:.4f}{acc} ({time.perf_counter() - t0:.0f} s)",
                  flush=True)
            sides = right = 0
        if step % args.eval_every == 0 or step == args.steps:
            evaluate(step, sum(losses[-50:]) / len(losses[-50:]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
