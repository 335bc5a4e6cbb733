"""Fine-tuning a (tiny) model on recorded trajectories rendered with the planner prompt, so that the tiny
planner acts sensibly: `adapt model pretrain --model DIR --data runs/oracle.jsonl --out DIR`.

Each record is replayed in the simulator (same scene, the offline user) to rebuild the view the agent
had at every step; the example is the rendered planner prompt (`fit` to the token budget) and the
recorded action followed by EOS. A record whose replay does not reproduce its observations (another
spec version) is skipped. Loss on the action tokens only; plain AdamW, one sequence per step.
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
    from ..harness.rollout import Job
    from ..runtime.env import Env
    from .rollout import episode_id

    persona, task = domain.persona[record["persona"]], domain.task[record["task"]]
    env = Env(domain, task.id, persona.id, record["seed"], user=OfflineUser(domain, persona, task))
    ep = Episode(episode_id(Job(record["agent"], persona.id, task.id, record["seed"])), env)
    out, made_after = [], []
    for step in record["steps"]:
        view = ep.view()
        out.append((view, tuple(made_after), step["action"]))
        ep.apply(Decision(step["action"]))
        if ep.history[-1].observation != step["observation"]:
            return None
        made_after.append(ep.view().made)
    return out


def examples(domain, records, tokenizer, budget: int | None = None, kind: str = "planner") -> tuple:
    """(prompt ids, target ids) per recorded step, and how many records were skipped."""
    from .chat import fit, render
    from .prompts import PromptBuilder

    builder = PromptBuilder(domain, kind)
    eos = tokenizer.eos_token_id
    out, skipped = [], 0
    for r in records:
        steps = replay_views(domain, r)
        if steps is None:
            skipped += 1
            continue
        for view, made_after, action in steps:
            prompt = fit(tokenizer, lambda o, v=view, m=made_after: builder.prompt(v, omit=o, made_after=m), budget)
            p = tokenizer(render(tokenizer, prompt), add_special_tokens=False)["input_ids"]
            t = tokenizer(action, add_special_tokens=False)["input_ids"] + [eos]
            out.append((p, t))
    return out, skipped


def train(model, data, steps: int, lr: float = 3e-3, seed: int = 0, log=None) -> list:
    """`steps` AdamW updates, one example each (cycled, shuffled); returns the loss per step."""
    import torch

    rng = random.Random(seed)
    torch.manual_seed(seed)
    order = list(range(len(data)))
    opt = torch.optim.AdamW(model.parameters(), lr=lr, weight_decay=0.0)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda i: min(1.0, (i + 1) / 50) * max(0.05, 1 - i / steps))
    model.train()
    losses, t0 = [], time.perf_counter()
    for i in range(steps):
        if i % len(order) == 0:
            rng.shuffle(order)
        p, t = data[order[i % len(order)]]
        ids = torch.tensor([p + t])
        logits = model(input_ids=ids, logits_to_keep=len(t) + 1).logits[0, :-1].float()
        loss = torch.nn.functional.cross_entropy(logits, torch.tensor(t))
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        sched.step()
        losses.append(loss.item())
        if log and (i + 1) % max(1, steps // 20) == 0:
            recent = losses[-max(1, steps // 20):]
            log(f"step {i + 1}/{steps} loss {sum(recent) / len(recent):.3f} ({time.perf_counter() - t0:.0f} s)")
    model.eval()
    return losses


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
    log(f"{len(data)} examples from {len(records) - skipped} episodes ({skipped} skipped)")
    losses = train(model, data, steps, lr, seed, log)
    Path(out).mkdir(parents=True, exist_ok=True)
    model.save_pretrained(out)
    tok.save_pretrained(out)
    return {"examples": len(data), "episodes": len(records) - skipped, "skipped": skipped, "steps": steps,
            "first_loss": sum(losses[:50]) / min(50, len(losses)), "last_loss": sum(losses[-50:]) / min(50, len(losses))}
