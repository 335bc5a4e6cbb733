"""Language-model side on the tiny model (CPU): constrained versus unconstrained decoding speed, batched
versus one-at-a-time rollouts, the share of a step spent outside the model, and LLM-user answers per
second batched (one generate for every episode that asks in a round) versus one at a time.

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


def _ask_rollout(domain, backend, jobs, width: int, steps: int) -> tuple:
    """One rollout of the scripted always-ask agent with LLM users: (answers, seconds, replies by episode)."""
    from adaptbench.agents.scripted import make_policy
    from adaptbench.llm.rollout import run_batched
    from adaptbench.llm.user import LLMUser

    users = []

    def user(d, p, t):
        users.append(LLMUser(backend, d, p, t))
        return users[-1]

    t = time.perf_counter()
    recs = list(run_batched(jobs, domain, make_policy("always-ask", domain), user, batch=width, steps=steps))
    wall = time.perf_counter() - t
    replies = sorted((r["persona"], r["task"], r["seed"], tuple(s["reply"] for s in r["steps"])) for r in recs)
    return sum(len(u.calls) for u in users), wall, replies


def user_answers_per_second(domain, backend, n: int, steps: int) -> tuple:
    """LLM-user answers per second (over the rollout's wall time) with the scripted always-ask agent on n
    episodes (2 personas x the tasks, seeds 0..n-1, `steps` steps each; it asks its questions first, so
    the episodes ask in the same rounds): (batched, one at a time, answers, whether the replies match)."""
    from adaptbench.harness.rollout import Job

    personas, tasks = list(domain.persona)[:2], list(domain.task)
    jobs = [Job("always-ask", personas[i % 2], tasks[i % len(tasks)], i) for i in range(n)]
    answers, wall_b, replies_b = _ask_rollout(domain, backend, jobs, n, steps)
    answers_1, wall_1, replies_1 = _ask_rollout(domain, backend, jobs, 1, steps)
    return answers / wall_b, answers_1 / wall_1, answers, replies_b == replies_1


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
    batched, single, prep, other = episodes_per_minute(domain, backend, n, 3 if quick else 5)
    ub, us, answers, same = user_answers_per_second(domain, backend, n, 3 if quick else 6)
    return [
        (f"llm: constrained tokens/s (batch {n})", con, "tok/s", "", ""),
        (f"llm: unconstrained tokens/s (batch {n})", unc, "tok/s", "", ""),
        ("llm: constrained / unconstrained", con / unc, "ratio", ">= 0.9", ""),
        (f"llm: episodes/min, {n} batched", batched, "ep/min", "", ""),
        ("llm: episodes/min, one at a time", single, "ep/min", "", ""),
        ("llm: batched / one at a time", batched / single, "ratio", ">= 4", ""),
        ("llm: prompt+grammar time / model time", prep, "share", "< 0.05", ""),
        ("llm: all non-model time / model time", other, "share", "< 0.05", "(simulator, user, prompts, grammar)"),
        (f"llm: user answers/s, {n} batched", ub, "answers/s", "", f"({answers} answers, scripted always-ask)"),
        ("llm: user answers/s, one at a time", us, "answers/s", "", "same replies" if same else "REPLIES DIFFER"),
        ("llm: user batched / one at a time", ub / us, "ratio", "", ""),
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
