"""Language-model side on the tiny model (CPU): constrained versus unconstrained decoding speed, batched
versus one-at-a-time rollouts, and the share of a step spent outside the model.

    python bench/bench_llm.py [--model DIR] [--quick]      # builds the tiny model when --model is absent

Needs the `models` extra. Figures go to docs/llm.md.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import SPEC, report  # noqa: E402


def _requests(domain, backend, n: int, grammar: bool):
    from adaptbench.grammars import GrammarCache
    from adaptbench.harness.episode import Episode
    from adaptbench.harness.rollout import Job
    from adaptbench.llm.backend import Request
    from adaptbench.llm.chat import render
    from adaptbench.llm.prompts import PromptBuilder
    from adaptbench.llm.rollout import episode_id
    from adaptbench.runtime.env import Env
    from adaptbench.runtime.index import runtime_index

    cache = GrammarCache(runtime_index(domain).grammar)
    out = []
    for i in range(n):
        task = list(domain.task)[i % len(domain.task)]
        ep = Episode(episode_id(Job("planner", "juan", task, i)), Env(domain, task, "juan", i))
        text = render(backend.tokenizer, PromptBuilder(domain, "planner").prompt(ep.view()))
        g = cache.state(task, ep.env.observed()).text if grammar else None
        out.append(Request(text, g, (), 32))
    return out


def decode_speed(domain, backend, n: int) -> tuple:
    """Generated tokens per second, constrained and unconstrained, same prompts, batch of n."""
    rates = []
    for grammar in (True, False):
        reqs = _requests(domain, backend, n, grammar)
        backend.generate(reqs[:2])  # warm
        t = time.perf_counter()
        outs = backend.generate(reqs)
        rates.append(sum(o.tokens for o in outs) / (time.perf_counter() - t))
    return tuple(rates)


def episodes_per_minute(domain, backend, n: int, steps: int) -> tuple:
    """(batched, one at a time) episodes per minute and the share of step time outside the model."""
    from adaptbench.agents.users import OfflineUser
    from adaptbench.harness.rollout import Job
    from adaptbench.llm.policies import LLMPolicy
    from adaptbench.llm.rollout import run_batched

    jobs = [Job("planner", "juan", list(domain.task)[i % 8], i) for i in range(n)]
    policy = LLMPolicy(backend, domain, "planner", max_tokens=24)

    def user(d, p, t):
        return OfflineUser(d, p, t)

    out = []
    for batch in (n, 1):
        t = time.perf_counter()
        recs = list(run_batched(jobs, domain, policy, user, batch=batch, steps=steps))
        wall = time.perf_counter() - t
        out.append(len(recs) / wall * 60)
        if batch == n:
            model = sum(s["stats"]["seconds"] / s["stats"]["batch"] for r in recs for s in r["steps"])
            prep = sum(s["stats"]["prepare_seconds"] for r in recs for s in r["steps"])
            other = wall - model
    return out[0], out[1], prep / model, other / model


def run(model: str | None, quick: bool) -> list:
    """Benchmark rows."""
    from adaptbench.compiler import load_domain
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.llm.tiny import init_tiny

    domain = load_domain(SPEC)
    if model is None:
        model = str(init_tiny(domain, Path(tempfile.mkdtemp()) / "tiny"))
    backend = TransformersBackend(model, batch_size=16)
    n = 8 if quick else 16
    con, unc = decode_speed(domain, backend, n)
    batched, single, prep, other = episodes_per_minute(domain, backend, n, 5 if quick else 20)
    return [
        (f"llm: constrained tokens/s (batch {n})", con, "tok/s", "", ""),
        (f"llm: unconstrained tokens/s (batch {n})", unc, "tok/s", "", ""),
        ("llm: constrained / unconstrained", con / unc, "ratio", ">= 0.9", ""),
        (f"llm: episodes/min, {n} batched", batched, "ep/min", "", ""),
        ("llm: episodes/min, one at a time", single, "ep/min", "", ""),
        ("llm: batched / one at a time", batched / single, "ratio", ">= 4", ""),
        ("llm: prompt+grammar time / model time", prep, "share", "< 0.05", ""),
        ("llm: all non-model time / model time", other, "share", "< 0.05", "(simulator, user, prompts, grammar)"),
    ]


def main() -> int:
    """Run and print."""
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--model", help="model directory (default: build the tiny model in a temp dir)")
    p.add_argument("--quick", action="store_true")
    args = p.parse_args()
    report(run(args.model, args.quick))
    return 0


if __name__ == "__main__":
    sys.exit(main())
