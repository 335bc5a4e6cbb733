"""Scoring throughput (issue 15's bar: batched >= 3x one at a time): continuations scored per second after
one planner prompt, in the same run,

- `batched`: one `backend.score(prompt, texts)` call (the prompt read once, the continuations after its
  cache: `llm.scoring`);
- `one_at_a_time`: one `backend.score(prompt, [text])` call per continuation;
- `forward_each`: what a user writes without the backend, a plain forward pass over prompt + continuation
  per continuation (what `score` did before, per call);
- `padded_batch`: the previous batched `score`: prompt + continuation per row, left-padded, one pass;

with the ratios and the largest difference between the batched and one-at-a-time log-probabilities.

    python bench/bench_score.py [--model DIR] [--n 16] [--reps 3] [--dtype float32] [--device cpu]
                                [--ways batched,one_at_a_time,forward_each,padded_batch]
                                # builds the (random) tiny model when --model is absent
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

ACTIONS = ("Look for eggs", "Move egg_0 to pan_0", "Open fridge_0", 'Ask "How do you like your eggs?"',
           "Turn on stove_0", "Declare Done", "Look for butter", "Cook egg_0 in pan_0 to get scrambled_eggs",
           "Search counter_0", "Move butter_0 to pan_0", "Close fridge_0", 'Ask "Any milk in the eggs?"',
           "Look for salt", "Move plate_0 to dining_table_0", "Look for pan", "Turn off stove_0")


WAYS = ("batched", "one_at_a_time", "forward_each", "padded_batch")


def prompt_text(backend, domain) -> str:
    """The planner's rendered prompt four steps into an eggs episode."""
    from tests.llm.conftest import play

    from adaptbench.llm.chat import render
    from adaptbench.llm.prompts import PromptBuilder

    return render(backend.tokenizer, PromptBuilder(domain, "planner").prompt(play(domain)[0].view()))


def _forward_each(backend, x: str, texts: list) -> None:
    import torch

    from adaptbench.llm.backend import continuation_ids

    p = backend.encode(x)
    with torch.no_grad():
        for t in texts:
            c = continuation_ids(backend.tokenizer, t)
            logits = backend.model(input_ids=torch.tensor([p + c], device=backend.device)).logits[0, len(p) - 1:-1]
            torch.log_softmax(logits.float(), -1)[torch.arange(len(c)), torch.tensor(c)].tolist()


def _padded_batch(backend, x: str, texts: list) -> None:
    """The previous `score`: every row prompt + continuation, left-padded, one pass per batch."""
    import torch

    from adaptbench.llm.backend import continuation_ids
    from adaptbench.llm.hf import _left_pad

    p = backend.encode(x)
    conts = [continuation_ids(backend.tokenizer, t) for t in texts]
    for i in range(0, len(conts), backend.batch_size):
        chunk = conts[i:i + backend.batch_size]
        ids, mask = _left_pad([p + c for c in chunk], backend.pad_id)
        keep = max(len(c) for c in chunk) + 1
        pos = (mask.cumsum(-1) - 1).clamp(min=0)
        with torch.no_grad():
            logits = backend.model(input_ids=ids.to(backend.device), attention_mask=mask.to(backend.device),
                                   position_ids=pos.to(backend.device), logits_to_keep=keep).logits
        torch.log_softmax(logits.float(), -1)


def measure(backend, x: str, texts: list, reps: int, ways=WAYS) -> dict:
    """Continuations per second each way (`ways`: which of `WAYS`; batched and one at a time always), the
    ratios and the batched-vs-alone agreement (from the timed calls' results)."""
    backend.score(x, texts[:2])  # warm up
    got: dict = {}
    fns = {"batched": lambda: got.__setitem__("batched", backend.score(x, texts)),
           "one_at_a_time": lambda: got.__setitem__("alone", [backend.score(x, [t])[0] for t in texts]),
           "forward_each": lambda: _forward_each(backend, x, texts),
           "padded_batch": lambda: _padded_batch(backend, x, texts)}
    rate = {}
    for name in dict.fromkeys(("batched", "one_at_a_time", *ways)):
        t0 = time.perf_counter()
        for _ in range(reps):
            fns[name]()
        rate[name] = len(texts) * reps / (time.perf_counter() - t0)
    diff = max(abs(a - b) for s, o in zip(got["batched"], got["alone"], strict=True)
               for a, b in zip(s.logprobs, o.logprobs, strict=True))
    return {"prompt_tokens": len(backend.encode(x)), "continuations": len(texts), "reps": reps,
            "per_s": {k: round(v, 2) for k, v in rate.items()},
            **{f"ratio_batched_vs_{k}": round(rate["batched"] / v, 2) for k, v in rate.items() if k != "batched"},
            "max_abs_diff_batched_vs_alone": float(f"{diff:.3g}")}


def main() -> None:
    """Measure and print JSON."""
    from adaptbench.compiler import load_domain
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.paper import default_spec

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model")
    ap.add_argument("--n", type=int, default=16)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--dtype", default="float32")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--ways", default=",".join(WAYS), help="which to time (batched and one_at_a_time always)")
    args = ap.parse_args()
    domain = load_domain(default_spec())
    with tempfile.TemporaryDirectory() as tmp:
        model = args.model
        if model is None:
            from adaptbench.llm.tiny import init_tiny

            model = str(init_tiny(domain, Path(tmp) / "tiny"))
        backend = TransformersBackend(model, device=args.device, dtype=args.dtype, batch_size=16)
        texts = [ACTIONS[i % len(ACTIONS)] for i in range(args.n)]
        out = {"model": model, "device": args.device, "dtype": args.dtype,
               **measure(backend, prompt_text(backend, domain), texts, args.reps, args.ways.split(","))}
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
