"""How much running a batch's shared system message once saves a training update (`training.shared_prefix`).

    python bench/bench_shared_prefix.py [--model student] [--repeats 3]

Builds one scene's answer rows and oracle episodes for split 0's training personas (whole planner
prompts), then times a forward and backward pass over a batch of 8 answer rows, and over 4 episodes, two
ways: every sequence run whole, one after the other (what `adapt model student --accumulate 8` does), and
with their common opening (the ~1,230-token system message) run once. Prints seconds an update (median of
`--repeats`), the ratio, and the largest difference in loss and gradient between the two ways. One thread,
as the student trains.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time


def plain_loss(model, sequences):
    """The mean of each sequence's mean token loss, every sequence run whole."""
    import torch

    losses = [model(input_ids=torch.tensor([ids]), labels=torch.tensor([labels])).loss for ids, labels in sequences]
    return torch.stack(losses).mean()


def timed(model, loss_fn, batch, repeats: int):
    """(median seconds of forward + backward, loss, flat gradient) of `loss_fn` on `batch`."""
    import torch

    times = []
    for _ in range(repeats):
        model.zero_grad()
        t = time.perf_counter()
        loss = loss_fn(model, batch)
        loss.backward()
        times.append(time.perf_counter() - t)
    grad = torch.cat([p.grad.flatten() for p in model.parameters() if p.grad is not None])
    return statistics.median(times), float(loss.detach()), grad


def main(argv=None) -> int:
    """Time plain and shared-prefix updates on answer rows and on episodes."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="student", help="a model name or directory (default: the shipped student)")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)

    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    from adaptbench.agents.scripted import play
    from adaptbench.agents.users import OfflineUser
    from adaptbench.compiler import load_domain
    from adaptbench.llm.named import resolve_model
    from adaptbench.runtime.env import Env
    from adaptbench.training.answer_rows import answer_examples, answer_rows
    from adaptbench.training.pretrain import examples
    from adaptbench.training.shared_prefix import common_prefix, shared_prefix_loss
    from adaptbench.training.student import training_personas

    torch.set_num_threads(1)
    domain = load_domain()
    path = resolve_model(args.model)
    tok = AutoTokenizer.from_pretrained(path)
    model = AutoModelForCausalLM.from_pretrained(path, dtype=torch.float32)
    personas = training_personas(domain, "0")
    rows = answer_examples(answer_rows(domain, personas[:2], range(100, 101))[:8], tok, "full")
    records = []
    for task in sorted(domain.task)[:4]:
        env = Env(domain, task, personas[0], 100, user=OfflineUser(domain, domain.persona[personas[0]], domain.task[task]))
        play("oracle", env)
        steps = [{"action": e.text, "ok": e.ok, "observation": e.observation, "reply": e.reply} for e in env.world.trace]
        records.append({"agent": "oracle", "persona": personas[0], "task": task, "seed": 100, "steps": steps})
    episodes, _ = examples(domain, records, tok, None)
    print("| batch | tokens | shared | whole, one by one (s) | shared prefix (s) | ratio | loss diff | grad diff |")
    print("|---|---|---|---|---|---|---|---|")
    for name, batch in (("8 answer rows", rows), ("4 oracle episodes", episodes)):
        t_plain, l_plain, g_plain = timed(model, plain_loss, batch, args.repeats)
        t_shared, l_shared, g_shared = timed(model, shared_prefix_loss, batch, args.repeats)
        print(f"| {name} | {sum(len(i) for i, _ in batch)} | {common_prefix(batch)} | {t_plain:.2f} | {t_shared:.2f} "
              f"| {t_plain / t_shared:.2f}x | {abs(l_plain - l_shared):.1e} | {float((g_plain - g_shared).abs().max()):.1e} |",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
