"""Rollout speed of a real model on the CPU under each setting of the transformers backend: torch
threads, episodes batched, the session key/value cache, the prompt token budget and the dtype, one
setting changed at a time from the default. Planner episodes, offline user, steps per second over the
rollout's wall time (model loading excluded).

    python bench/bench_llm.py --model models/smollm2 --settings [--quick]

Figures go to docs/smollm2.md.
"""

from __future__ import annotations

import time


def _steps_per_second(domain, model: str, episodes: int, steps: int, threads: int, batch: int,
                      sessions: bool, budget: int | None, dtype: str) -> tuple:
    from adaptbench.llm.rollout import run_batched

    from adaptbench.agents.users import OfflineUser
    from adaptbench.harness.rollout import Job
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.llm.policies import LLMPolicy

    backend = TransformersBackend(model, dtype=dtype, batch_size=batch, threads=threads,
                                  **({} if sessions else {"sessions": 0}))
    policy = LLMPolicy(backend, domain, "planner", budget=budget)
    tasks = list(domain.task)
    jobs = [Job("planner", "juan", tasks[i % len(tasks)], i) for i in range(episodes)]

    def user(d, p, t):
        return OfflineUser(d, p, t)

    t = time.perf_counter()
    recs = list(run_batched(jobs, domain, policy, user, batch=batch, steps=steps))
    wall = time.perf_counter() - t
    n = sum(len(r["steps"]) for r in recs)
    prompt = sum(s["stats"].get("prompt_tokens", 0) for r in recs for s in r["steps"]) / max(n, 1)
    return n / wall, n, wall, prompt


DEFAULT = {"threads": 2, "batch": 16, "sessions": True, "budget": None, "dtype": "float32"}
VARY = (("threads", 1), ("batch", 4), ("batch", 1), ("budget", 1024), ("dtype", "bfloat16"), ("sessions", False),
        ("dtype+batch", ("bfloat16", 4)))  # the last: the default chosen for models of this size (llm/cpu.py)


def run(domain, model: str, quick: bool = False) -> list:
    """Benchmark rows: steps/s of the default setting and of each one-setting change (the session-cache
    change on a quarter of the episodes: without it every step reads its whole prompt again)."""
    episodes, steps = (4, 2) if quick else (16, 4)
    for dtype in ("float32", "bfloat16"):  # warm-up: first calls, grammar and tokenizer caches
        _steps_per_second(domain, model, 1, 1, **{**DEFAULT, "dtype": dtype})
    rows = []
    base = None
    for key, value in ((None, None), *VARY):
        s = dict(DEFAULT) if key is None else {**DEFAULT, key: value} if "+" not in key else \
            {**DEFAULT, **dict(zip(key.split("+"), value, strict=True))}
        n_ep = max(1, episodes // 4) if key == "sessions" else episodes
        if key == "sessions":  # the same smaller set with the cache, for the ratio
            ref = _steps_per_second(domain, model, n_ep, steps, **{**DEFAULT, "batch": min(DEFAULT["batch"], n_ep)})
        s["batch"] = min(s["batch"], n_ep)
        rate, n, wall, prompt = _steps_per_second(domain, model, n_ep, steps, **s)
        label = "default" if key is None else f"{key} {value}"
        if key is None:
            base = rate
        ratio = rate / (ref[0] if key == "sessions" else base)
        rows.append((f"llm settings: {label} ({n_ep} ep x {steps} steps)", rate, "steps/s", "",
                     f"{ratio:.2f} x default; {n} steps in {wall:.0f} s, mean prompt {prompt:.0f} tok"))
    return rows
