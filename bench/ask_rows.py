"""Teach a cook when to ask by training only the rows of the tokens that choose a question.

    python bench/ask_rows.py --model student --episodes runs/own/episodes.jsonl --plain runs/plain.jsonl \\
        --out runs/own/R [--steps 200] [--lr 1e-2]

The shipped student was cloned on episodes without questions, so for thousands of updates the softmax
pushed the logit of `Ask` (the first token of every question) down at every step: on its own episodes with
the oracle's questions inserted (`bench/ask_in_own_cooking.py`) it puts ~17 nats on it. Fine-tuning the
whole model at lr 5e-4 breaks its cooking within 50 updates; at lr 1e-4, 100 updates move the 17 nats by
under 2 and still cost a third of its dishes (docs/training.md, twenty-second session).

This trains nothing but the embedding rows (tied: input and output) of the tokens where a `bank` decoder
chooses a question (`training.forced_tokens`: `Ask` itself and each token where two bank questions part)
that the student does not also read or write while it cooks (`cooking_tokens`: none of `--plain`'s), with
their own learning rate, on the episodes' whole-episode loss (forced question tokens masked). Every other
weight is frozen, so where the student does not ask, its hidden states are those of the cook it was:
learning when to ask becomes a linear read-out of the cook's own state. Prints the loss and the `Ask`
token's mean negative log-likelihood where the oracle asked as it goes. Not a shipped model: a measurement.
"""

from __future__ import annotations

import argparse
import random
import sys
import time


def ask_token(tok) -> int:
    """The first token of every question action (`Ask `)."""
    return tok('Ask "x"', add_special_tokens=False)["input_ids"][0]


def question_rows(tok, questions) -> list:
    """The token ids a `bank` decoder chooses among inside a question: `Ask` and the trie's branching
    children."""
    from adaptbench.training.forced_tokens import question_trie

    rows, stack = set(), [question_trie(tok, questions)]
    while stack:
        node = stack.pop()
        if len(node) > 1:  # a choice: every child is a row to train
            rows.update(node)
        stack.extend(node.values())
    return sorted(rows | {ask_token(tok)})


def cooking_tokens(plain: list) -> set:
    """Tokens the student reads or writes while it cooks: every token of episodes without a question."""
    return {t for ids, _ in plain for t in ids}


def ask_nll(model, episodes: list, ask: int, eos: int) -> tuple:
    """(mean NLL of `Ask` where the episodes ask, how many such steps): the first token of each action."""
    import torch

    from adaptbench.training.pretrain import IGNORE

    total, n = 0.0, 0
    with torch.no_grad():
        for ids, labels in episodes:
            lp = torch.log_softmax(model(input_ids=torch.tensor([ids])).logits[0, :-1], -1)
            for i in range(1, len(ids)):
                if labels[i] == ask and labels[i - 1] in (IGNORE, eos):
                    total, n = total - lp[i - 1, ask].item(), n + 1
    return total / max(n, 1), n


def main(argv=None) -> int:
    """Train the question rows only; save the model."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="student", help="model to start from (a name or a directory)")
    ap.add_argument("--episodes", required=True, nargs="+", help="episode records with questions (JSONL)")
    ap.add_argument("--plain", required=True, nargs="+",
                    help="episode records without questions (the student's own): their tokens are not trained")
    ap.add_argument("--out", required=True, help="directory for the model")
    ap.add_argument("--steps", type=int, default=200, help="updates")
    ap.add_argument("--episodes-per-update", type=int, default=4)
    ap.add_argument("--lr", type=float, default=1e-2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)

    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    from adaptbench.compiler import load_domain
    from adaptbench.grammars.index import domain_questions
    from adaptbench.llm.named import resolve_model
    from cook_and_read import (  # bench/, beside this file
        batches,
        episode_examples,
        episode_losses,
        training_episodes,
    )

    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    domain, path = load_domain(), resolve_model(args.model)
    tok = AutoTokenizer.from_pretrained(path)
    model = AutoModelForCausalLM.from_pretrained(path, dtype=torch.float32)
    episodes = training_episodes(domain, tok, args.episodes, mask=True)
    ask = ask_token(tok)
    shared = cooking_tokens(episode_examples(domain, tok, args.plain))
    rows = [t for t in question_rows(tok, domain_questions(domain)) if t == ask or t not in shared]
    probe = episodes[:12]
    for p in model.parameters():
        p.requires_grad_(False)
    emb = model.get_input_embeddings().weight
    emb.requires_grad_(True)
    keep = torch.zeros(emb.shape[0], 1)
    keep[rows] = 1.0
    emb.register_hook(lambda g: g * keep)  # only the question rows learn
    opt = torch.optim.Adam([emb], lr=args.lr)
    print(f"{len(episodes)} episodes; training rows {tok.convert_ids_to_tokens(rows)}; "
          f"Ask NLL where the oracle asks: {ask_nll(model, probe, ask, tok.eos_token_id)[0]:.2f}", flush=True)
    order = batches(len(episodes), args.episodes_per_update, random.Random(args.seed))
    t0, losses = time.perf_counter(), []
    for step in range(1, args.steps + 1):
        opt.zero_grad()
        loss = torch.stack(episode_losses(model, [episodes[i] for i in next(order)])).mean()
        loss.backward()
        opt.step()
        losses.append(loss.item())
        if step % 25 == 0 or step == args.steps:
            nll = ask_nll(model, probe, ask, tok.eos_token_id)[0]
            print(f"update {step}: loss {sum(losses[-25:]) / len(losses[-25:]):.3f}, Ask NLL {nll:.2f} "
                  f"({time.perf_counter() - t0:.0f} s)", flush=True)
    model.save_pretrained(args.out)
    tok.save_pretrained(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
