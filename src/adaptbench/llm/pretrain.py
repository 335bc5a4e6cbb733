"""Fine-tuning a (tiny) model on recorded trajectories rendered with the planner prompt, so that the tiny
planner acts sensibly: `adapt model pretrain --model DIR --data runs/oracle.jsonl --out DIR`.

Each record is replayed in the simulator (same scene, the offline user) to rebuild the view the agent
had at every step; the target is the recorded action followed by EOS after the rendered planner prompt
(`fit` to the token budget). Each step's untruncated prompt is a prefix of the next one's, so the steps
that fit the budget are packed into one sequence per episode (with no budget: the whole episode) and
one forward pass trains them all; a step whose prompt has to drop old steps is a sequence of its own.
A record whose replay does not reproduce its observations (another spec version) is skipped. Loss on
the action tokens only; plain AdamW, one sequence per update.
"""

from __future__ import annotations

import json
import random
import time
from pathlib import Path


def read_records(paths) -> list:
    """Episode records from JSONL files (error records and unreadable lines skipped)."""
    out = []
    for p in paths:
        for line in Path(p).read_text().splitlines():
            try:
                r = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(r, dict) and "steps" in r and "error" not in r:
                out.append(r)
    return out


def replay_views(domain, record):
    """(view, made_after, action) for each step of a record, rebuilt by replaying it; None when the
    replay's observations differ from the record's."""
    from ..agents.users import OfflineUser
    from ..harness.episode import Episode
    from ..harness.policy import Decision
    from ..runtime.env import Env

    persona, task = domain.persona[record["persona"]], domain.task[record["task"]]
    env = Env(domain, task.id, persona.id, record["seed"], user=OfflineUser(domain, persona, task))
    ep = Episode(f"{record['agent']}/{persona.id}/{task.id}/{record['seed']}", env)  # the rollout's episode id
    out, made_after = [], []
    for step in record["steps"]:
        view = ep.view()
        out.append((view, tuple(made_after), step["action"]))
        ep.apply(Decision(step["action"]))
        if ep.history[-1].observation != step["observation"]:
            return None
        made_after.append(ep.view().made)
    return out


IGNORE = -100  # label of a token the loss skips


def examples(domain, records, tokenizer, budget: int | None = None, kind: str = "planner") -> tuple:
    """Training sequences `(ids, labels)` (labels: the target token, or IGNORE where there is no loss)
    and how many records were skipped. An episode's steps whose full prompt fits the budget are packed
    into one sequence (each step's prompt is a prefix of the next one's, so one pass trains them all);
    a later step, whose prompt drops old steps, is a sequence of its own."""
    from .prompts import PromptBuilder

    builder = PromptBuilder(domain, kind)
    out, skipped = [], 0
    for r in records:
        steps = replay_views(domain, r)
        if steps is None:
            skipped += 1
            continue
        out += episode_examples(builder, tokenizer, steps, budget)
    return out, skipped


def episode_examples(builder, tokenizer, steps, budget: int | None = None) -> list:
    """The `(ids, labels)` sequences of one replayed episode (see `examples`)."""
    packed, n = packed_example(builder, tokenizer, steps, budget)
    return ([packed] if packed else []) + [step_example(builder, tokenizer, s, budget) for s in steps[n:]]


def step_example(builder, tokenizer, step, budget: int | None) -> tuple:
    """One step: its prompt (`fit` to the budget) with no loss, then the action and EOS."""
    from .chat import fit, render

    view, made_after, action = step
    prompt = fit(tokenizer, lambda o: builder.prompt(view, omit=o, made_after=made_after), budget)
    p = tokenizer(render(tokenizer, prompt), add_special_tokens=False)["input_ids"]
    t = tokenizer(action, add_special_tokens=False)["input_ids"] + [tokenizer.eos_token_id]
    return p + t, [IGNORE] * len(p) + t


def packed_example(builder, tokenizer, steps, budget: int | None) -> tuple:
    """The longest run of leading steps whose untruncated prompts fit the budget as one sequence (the
    last of them with its action and EOS), labels on every action and EOS; and how many steps it holds.
    (None, 0) when the tokenizer does not split the conversation where the actions start and end (the
    action would then be tokenized differently in the history than when generated)."""
    from .chat import render

    eos = tokenizer.eos_token
    view, made_after, action = steps[-1]
    text = render(tokenizer, builder.prompt(view, made_after=made_after)) + action + eos
    spans = []
    for view, made_after, action in steps:
        start = len(render(tokenizer, builder.prompt(view, made_after=made_after)))
        if text[start:start + len(action) + len(eos)] != action + eos:
            return None, 0
        spans.append((start, action))
    enc = tokenizer(text, add_special_tokens=False, return_offsets_mapping=True)
    ids, begins = enc["input_ids"], {b: i for i, (b, _) in enumerate(enc["offset_mapping"])}
    labels, n, end = [IGNORE] * len(ids), 0, 0
    for start, action in spans:
        first = begins.get(start)
        target = tokenizer(action, add_special_tokens=False)["input_ids"] + [tokenizer.eos_token_id]
        if first is None or ids[first:first + len(target)] != target:
            return None, 0
        if budget is not None and first > budget:
            break
        labels[first:first + len(target)] = target
        n, end = n + 1, first + len(target)
    return ((ids[:end], labels[:end]) if n else None), n


def train(model, data, steps: int, lr: float = 3e-3, seed: int = 0, log=None) -> list:
    """`steps` AdamW updates, one sequence each (cycled, shuffled; the loss is the mean over its labelled
    tokens); returns the loss per update."""
    import torch

    rng = random.Random(seed)
    torch.manual_seed(seed)
    order = list(range(len(data)))
    opt = torch.optim.AdamW(model.parameters(), lr=lr, weight_decay=0.0)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda i: min(1.0, (i + 1) / 50) * max(0.05, 1 - i / steps))
    model.train()
    losses, t0, every = [], time.perf_counter(), max(1, steps // 20)
    for i in range(steps):
        if i % len(order) == 0:
            rng.shuffle(order)
        loss = sequence_loss(model, *data[order[i % len(order)]])
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        sched.step()
        losses.append(loss.item())
        if log and (i + 1) % every == 0:
            spent = time.perf_counter() - t0
            log(f"update {i + 1}/{steps} loss {sum(losses[-every:]) / every:.3f} "
                f"({spent:.0f} s, ~{spent / (i + 1) * (steps - i - 1):.0f} s left)")
    model.eval()
    return losses


def sequence_loss(model, ids, labels):
    """Mean cross-entropy of the labelled tokens of one sequence; the output layer is applied to the
    positions that predict them only."""
    import torch

    where = [i - 1 for i, t in enumerate(labels) if t != IGNORE]
    hidden = model.base_model(input_ids=torch.tensor([ids])).last_hidden_state[0, where]
    logits = model.get_output_embeddings()(hidden).float()
    return torch.nn.functional.cross_entropy(logits, torch.tensor([labels[i + 1] for i in where]))


def pretrain(domain, model_dir, data_paths, out, steps: int = 2000, lr: float = 3e-3, budget: int | None = None,
             seed: int = 0, threads: int = 1, log=print) -> dict:
    """Fine-tune the model in `model_dir` on the records in `data_paths`; save to `out`."""
    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    torch.set_num_threads(threads)
    tok = AutoTokenizer.from_pretrained(model_dir)
    model = AutoModelForCausalLM.from_pretrained(model_dir, dtype=torch.float32)
    records = read_records(data_paths)
    data, skipped = examples(domain, records, tok, budget)
    if not data:
        raise ValueError(f"no training examples in {', '.join(map(str, data_paths))} "
                         f"({len(records)} records, {skipped} not reproducible with this spec)")
    targets = sum(1 for _, labels in data for t in labels if t == tok.eos_token_id)
    log(f"{targets} steps of {len(records) - skipped} episodes ({skipped} skipped) in {len(data)} sequences, "
        f"{sum(len(ids) for ids, _ in data)} tokens")
    losses = train(model, data, steps, lr, seed, log)
    Path(out).mkdir(parents=True, exist_ok=True)
    model.save_pretrained(out)
    tok.save_pretrained(out)
    return {"examples": targets, "sequences": len(data), "episodes": len(records) - skipped, "skipped": skipped, "steps": steps,
            "first_loss": sum(losses[:50]) / min(50, len(losses)), "last_loss": sum(losses[-50:]) / min(50, len(losses))}
