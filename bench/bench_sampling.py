"""What a generator per row costs (`llm/sampling.py`), on the CPU, in one run:

- per decoding step: picking B rows' tokens from [B, V] logits with `RowSampler` (each row its own
  softmax and `torch.multinomial` with its own generator) against one batched `torch.multinomial` with
  one shared generator (what the backend did before: samples then depended on the batch) and greedy
  `argmax`, for the tiny model's vocabulary (4,096) and SmolLM2's (49,152);
- end to end: a batch of 16 constrained requests of 24 tokens on the tiny model, sampled with a key per
  request (a generator each) against greedy.

    python bench/bench_sampling.py [--model DIR] [--rows 16]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import SPEC, timeit  # noqa: E402


def per_step(rows: int, vocab: int) -> list:
    import torch

    from adaptbench.llm.sampling import RowSampler, generator

    torch.set_num_threads(1)  # as the backend runs on the CPU
    logits = torch.randn(rows, vocab)
    shared = generator(0)
    ours = RowSampler([1.0] * rows, [generator(i) for i in range(rows)])
    t_ours = timeit(lambda: ours.pick(logits), repeat=5, number=10)
    t_batched = timeit(lambda: torch.multinomial(torch.softmax(logits, -1), 1, generator=shared), repeat=5, number=10)
    t_greedy = timeit(lambda: logits.argmax(-1), repeat=5, number=10)
    return [(f"pick {rows} rows, V={vocab}: a generator per row", t_ours * 1e6, "us/step", "",
             f"{t_ours / t_batched:.2f}x one shared batched multinomial ({t_batched * 1e6:.0f} us), "
             f"greedy argmax {t_greedy * 1e6:.0f} us")]


def end_to_end(model: str, rows: int) -> list:
    from adaptbench.compiler import load_domain
    from adaptbench.grammars import GrammarCache
    from adaptbench.harness.episode import Episode
    from adaptbench.llm.backend import Request
    from adaptbench.llm.chat import render
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.llm.prompts import PromptBuilder
    from adaptbench.runtime.env import Env
    from adaptbench.runtime.index import runtime_index

    d = load_domain(SPEC)
    ep = Episode("planner/juan/eggs/0", Env(d, "eggs", "juan", 0))
    out = []
    times = {}
    for t in (0.0, 1.0):
        b = TransformersBackend(model, temperature=t, sessions=0)
        text = render(b.tokenizer, PromptBuilder(d, "planner").prompt(ep.view()))
        g = GrammarCache(runtime_index(d).grammar).state("eggs", ep.env.observed()).text
        reqs = [Request(text, g, (), 24, key=f"k/{i}") for i in range(rows)]
        b.generate(reqs)  # warm: matchers built
        times[t] = timeit(lambda b=b, reqs=reqs: b.generate(reqs), repeat=5)
    out.append((f"generate {rows} constrained rows x 24 tokens, sampled", times[1.0], "s", "",
                f"{times[1.0] / times[0.0]:.2f}x greedy ({times[0.0]:.3f} s)"))
    return out


def main() -> None:
    from bench.common import report

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", help="model directory (default: a fresh tiny model)")
    ap.add_argument("--rows", type=int, default=16)
    a = ap.parse_args()
    rows = per_step(a.rows, 4096) + per_step(a.rows, 49152)
    with tempfile.TemporaryDirectory() as tmp:
        model = a.model
        if model is None:
            from adaptbench.compiler import load_domain
            from adaptbench.llm.tiny import init_tiny

            model = str(init_tiny(load_domain(SPEC), Path(tmp) / "tiny"))
        rows += end_to_end(model, a.rows)
    report(rows)


if __name__ == "__main__":
    main()
