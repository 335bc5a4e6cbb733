"""Language-model side (the tiny model by default; any model directory, or SmolLM2-135M's shape with random
weights): planner steps per second at batch 1, 16 and 64 (b episodes together) with the share of wall
time spent outside the model, against the plain way in the same run (`model.generate`, one episode,
every step's prompt read whole); constrained versus unconstrained decoding speed; and LLM-user answers
per second batched (one generate for every episode that asks in a round) versus one at a time.

    python bench/bench_llm.py [--model DIR] [--quick] [--device cuda] [--dtype bfloat16]
                                                 # builds the tiny model when --model is absent
    python bench/bench_llm.py --shape smollm2 [--model DIR] --quick   # SmolLM2-135M's shape, random weights
    python bench/bench_llm.py --model models/smollm2 --settings   # a real model's settings (llm_settings.py)
    python bench/bench_llm.py --model models/smollm2 --episode    # one row: tokens/s at batch 1, and one
                                                 # 50-step planner episode as `adapt rollout` runs it

Needs the `models` extra. Figures go to docs/llm.md.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import SPEC, report  # noqa: E402


def _requests(domain, backend, n: int, grammar: bool):
    from adaptbench.grammars import GrammarCache
    from adaptbench.harness.batches import episode_id
    from adaptbench.harness.episode import Episode
    from adaptbench.harness.rollout import Job
    from adaptbench.llm.backend import Request
    from adaptbench.llm.chat import render
    from adaptbench.llm.prompts import PromptBuilder
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


def decode_speed(domain, backend, n: int, rounds: int = 3) -> tuple:
    """Decoding tokens per second, constrained and unconstrained, on the same prompts, batch of n, and
    the same number of tokens per row (the unconstrained rows stop where the grammar ended the
    constrained ones: an action is short, and free-running rows would spread the first token's
    mask over more tokens): tokens after each row's first over the time after the prompts were read
    (`read_seconds`, timed inside the same call). Best of `rounds` interleaved rounds."""
    con = _requests(domain, backend, n, True)
    lengths = [o.tokens for o in backend.generate(con)]  # also warms
    unc = [type(r)(r.prompt, None, (), max(k, 1)) for r, k in zip(con, lengths, strict=True)]
    best = {True: 0.0, False: 0.0}
    for _ in range(rounds):
        for grammar, reqs in ((True, con), (False, unc)):
            outs = backend.generate(reqs)
            # one call per batch of rows: its wall and reading times are on every completion of it
            calls = {(o.stats["seconds"], o.stats["read_seconds"]) for o in outs}
            decoding = sum(sec - read for sec, read in calls)
            best[grammar] = max(best[grammar], (sum(o.tokens for o in outs) - len(outs)) / max(decoding, 1e-9))
    return best[True], best[False]


def _rollout(domain, backend, n: int, steps: int, batch: int) -> tuple:
    """(episodes per minute, records) of n planner episodes of `steps` steps, `batch` at a time."""
    from adaptbench.agents.users import OfflineUser
    from adaptbench.harness.batches import run_batched
    from adaptbench.harness.rollout import Job
    from adaptbench.llm.policies import LLMPolicy

    jobs = [Job("planner", "juan", list(domain.task)[i % 8], i) for i in range(n)]
    policy = LLMPolicy(backend, domain, "planner", max_tokens=24)

    def user(d, p, t):
        return OfflineUser(d, p, t)

    t = time.perf_counter()
    recs = list(run_batched(jobs, domain, policy, user, batch=batch, steps=steps))
    wall = time.perf_counter() - t
    return len(recs) / wall * 60, recs, wall


class _InStep:
    """An LLM user that answers inside its step only (no `prepare_answers`): the unbatched path."""

    def __init__(self, user):
        self.user, self.calls = user, user.calls

    def bind(self, env):
        """Bind the wrapped user."""
        self.user.bind(env)
        return self

    def answer(self, question, dialogue=()):
        """The wrapped user's answer, computed now."""
        return self.user.answer(question, dialogue)


def _ask_rollout(domain, backend, jobs, width: int, steps: int, batch_users: bool = True) -> tuple:
    """One rollout of the scripted always-ask agent with LLM users: (answers, seconds, replies by episode)."""
    from adaptbench.agents.scripted import make_policy
    from adaptbench.harness.batches import run_batched
    from adaptbench.llm.user import LLMUser

    users = []

    def user(d, p, t):
        users.append(LLMUser(backend, d, p, t) if batch_users else _InStep(LLMUser(backend, d, p, t)))
        return users[-1]

    t = time.perf_counter()
    recs = list(run_batched(jobs, domain, make_policy("always-ask", domain), user, batch=width, steps=steps))
    wall = time.perf_counter() - t
    replies = sorted((r["persona"], r["task"], r["seed"], tuple(s["reply"] for s in r["steps"])) for r in recs)
    return sum(len(u.calls) for u in users), wall, replies


def user_answers_per_second(domain, backend, n: int, steps: int) -> tuple:
    """LLM-user answers per second (over the rollout's wall time) with the scripted always-ask agent on n
    episodes (2 personas x the tasks, seeds 0..n-1, `steps` steps each; it asks its questions first, so
    the episodes ask in the same rounds): {batched, in_step (n episodes together, each user answering in
    its step), single (one episode at a time)} answers/s, the answers, and whether the replies match."""
    from adaptbench.harness.rollout import Job

    personas, tasks = list(domain.persona)[:2], list(domain.task)
    jobs = [Job("always-ask", personas[i % 2], tasks[i % len(tasks)], i) for i in range(n)]
    out, replies = {}, []
    for name, width, batch_users in (("batched", n, True), ("in_step", n, False), ("single", 1, True)):
        answers, wall, rep = _ask_rollout(domain, backend, jobs, width, steps, batch_users)
        out[name] = answers / wall
        replies.append(rep)
    return out, answers, all(r == replies[0] for r in replies)


def _timed_rollout(domain, backend, n: int, steps: int, batch: int) -> dict:
    """n planner episodes of `steps` steps, `batch` at a time: steps, wall and CPU seconds, and the model's
    seconds (each generate call's time, counted once)."""
    backend.batch_size = max(1, batch)
    if backend.sessions.limit:
        backend.sessions.limit = max(backend.sessions.limit, 2 * batch)  # every running episode keeps its cache
    cpu = time.process_time()
    _, recs, wall = _rollout(domain, backend, n, steps, batch)
    cpu = time.process_time() - cpu
    done = sum(len(r["steps"]) for r in recs)
    model = sum(s["stats"]["seconds"] / s["stats"]["batch"] for r in recs for s in r["steps"])
    return {"steps": done, "wall": wall, "cpu": cpu, "model": model}


def steps_per_second(domain, backend, plain, batches, steps: int, passes=(None,)) -> dict:
    """Planner steps per second at each batch size b (b episodes of `steps` steps together, offline
    user), with the share of the wall time spent outside the model and CPU seconds per step, under
    each decoding pass (`llm.batch_pass` modes; None: the device's default); and the plain way, one
    episode with `model.generate` reading every step's prompt whole (no cache)."""
    out = {}
    for name in passes:
        with _decoding_pass(backend, name):
            out.update({(name, b): _timed_rollout(domain, backend, b, steps, b) for b in batches})
    out["plain"] = _timed_rollout(domain, plain, 1, steps, 1)
    return out


@contextmanager
def _decoding_pass(backend, name: str | None):
    """Decode through this pass: a `llm.batch_pass` mode, optionally with its lanes (`graphs:1`: the
    graphed pass in one lane, no overlap; `llm.lanes`); None: the device's default."""
    from adaptbench.llm import batch_pass, lanes

    before = os.environ.get(lanes.LANES_ENV)
    mode, _, count = (name or "").partition(":")
    if mode:
        batch_pass.set_mode(backend.model, mode)
    if count:
        os.environ[lanes.LANES_ENV] = count
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(lanes.LANES_ENV, None)
        else:
            os.environ[lanes.LANES_ENV] = before


def profiled(domain, backend, batch: int, steps: int, out: str) -> None:
    """Profile one rollout of `batch` episodes (torch.profiler, CPU and CUDA where there is one) and
    write its operators by total time, and the Python functions by cumulative time, to `out`."""
    import cProfile
    import io
    import pstats

    import torch
    from torch.profiler import ProfilerActivity, profile

    acts = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if torch.cuda.is_available() else [])
    with profile(activities=acts) as prof:
        t = _timed_rollout(domain, backend, batch, steps, batch)
    sort = "cuda_time_total" if torch.cuda.is_available() else "cpu_time_total"
    text = [f"{t['steps']} steps in {t['wall']:.2f} s (model {t['model']:.2f} s)",
            prof.key_averages().table(sort_by=sort, row_limit=30)]
    py = cProfile.Profile()
    py.enable()
    _timed_rollout(domain, backend, batch, steps, batch)
    py.disable()
    buf = io.StringIO()
    pstats.Stats(py, stream=buf).sort_stats("cumulative").print_stats(40)
    Path(out).write_text("\n".join(text) + "\n" + buf.getvalue())


def _step_rows(table: dict, batches, steps: int, passes=(None,)) -> list:
    plain = table["plain"]["steps"] / table["plain"]["wall"]
    rows = []
    for name in passes:
        tag = "" if name is None else f"{name}: "
        for b in batches:
            t = table[(name, b)]
            rate = t["steps"] / t["wall"]
            rows += [(f"llm: {tag}steps/s, batch {b}", rate, "steps/s", ">= 1000" if b == 64 else "",
                      f"({b} ep x {steps} steps; {t['cpu'] / t['steps']:.3g} CPU s/step)"),
                     (f"llm: {tag}non-model share, batch {b}", (t["wall"] - t["model"]) / t["wall"], "share",
                      "< 0.05", "(simulator, user, prompts, grammar: wall time outside generate)"),
                     (f"llm: {tag}batch {b} / model.generate one at a time", rate / plain, "ratio", "", "")]
        if 1 in batches and 16 in batches:
            ratio = (table[(name, 16)]["steps"] / table[(name, 16)]["wall"]) / \
                (table[(name, 1)]["steps"] / table[(name, 1)]["wall"])
            rows.append((f"llm: {tag}batched 16 / one at a time", ratio, "ratio", ">= 4", "(GPU target)"))
    rows.append(("llm: steps/s, model.generate one at a time", plain, "steps/s", "", "(no cache between steps)"))
    named = [p for p in passes if p not in (None, "hf")]
    if "hf" in passes:
        for name in named:
            for b in batches:
                ratio = (table[(name, b)]["steps"] / table[(name, b)]["wall"]) / \
                    (table[("hf", b)]["steps"] / table[("hf", b)]["wall"])
                rows.append((f"llm: {name} / hf, batch {b}", ratio, "ratio", "", "(decoding pass against the "
                             "model's forward)"))
    rate = {k: t["steps"] / t["wall"] for k, t in table.items() if k != "plain"}
    for name in (p for p in passes if p and ":" in p and p.partition(":")[0] in passes):
        mode = name.partition(":")[0]
        rows += [(f"llm: {mode} / {name}, batch {b}", rate[(mode, b)] / rate[(name, b)], "ratio", "",
                  "(the device's lanes against these: llm/lanes.py)") for b in batches]
    return rows


def run(model: str | None, quick: bool, device: str = "cpu", dtype: str = "auto", threads: int | None = None,
        batches=(1, 16, 64), passes=(None,), steps: int | None = None, profile: str | None = None) -> list:
    """Benchmark rows. A real-sized model (100 MB of weights or more, `llm.cpu`) gets a shorter quick run:
    steps/s at each batch size and decoding at batch 1 (no LLM-user rows). `passes`: decoding passes
    to compare (`llm.batch_pass` modes); `steps`: each episode's steps in the steps/s rows; `profile`: a
    file for the operator profile of one more rollout at the largest batch (`profiled`)."""
    from adaptbench.compiler import load_domain
    from adaptbench.llm.cpu import LARGE, cpu_defaults, weight_bytes
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.llm.tiny import init_tiny

    domain = load_domain(SPEC)
    if model is None:
        model = str(init_tiny(domain, Path(tempfile.mkdtemp()) / "tiny"))
    large = weight_bytes(model) >= LARGE
    if device == "cpu" and dtype == "auto":
        dtype = cpu_defaults(model).dtype
        threads = threads or cpu_defaults(model).threads
    backend = TransformersBackend(model, device=device, dtype=dtype, batch_size=16, threads=threads or 1)
    plain = TransformersBackend(model, device=device, dtype=dtype, batch_size=1, sessions=0, threads=threads or 1)
    plain.loop = False  # model.generate, every step's prompt read whole: what a user would write
    settings = [(f"llm: settings: {device} {dtype}, {torch_threads()} torch threads", weight_bytes(model) / 2**20, "MB",
                 "", f"(model {model})")]
    n, per = (8, 5) if quick else (16, 20)
    if large:
        per = 2 if quick else 6
    per = steps or (3 if quick and not large else per)
    table = steps_per_second(domain, backend, plain, batches, per, passes)
    rows = settings + _step_rows(table, batches, per, passes)
    if profile:
        profiled(domain, backend, max(batches), per, profile)
    con1, unc1 = decode_speed(domain, backend, 1, 1 if quick else 3)
    rows += [("llm: constrained decoding tokens/s (batch 1)", con1, "tok/s", ">= 25" if large else "",
              "(prompt reading timed apart)"),
             ("llm: unconstrained decoding tokens/s (batch 1)", unc1, "tok/s", "", ""),
             ("llm: constrained / unconstrained (batch 1)", con1 / unc1, "ratio", ">= 0.9", "(forced tokens fast-forwarded)")]
    if large and quick:
        return rows
    con, unc = decode_speed(domain, backend, n, 1 if quick else 3)
    ua, answers, same = user_answers_per_second(domain, backend, n, 3 if quick else 6)
    return rows + [
        (f"llm: constrained decoding tokens/s (batch {n})", con, "tok/s", "", "(prompt reading timed apart)"),
        (f"llm: unconstrained decoding tokens/s (batch {n})", unc, "tok/s", "", ""),
        ("llm: constrained / unconstrained", con / unc, "ratio", ">= 0.9", "(forced tokens fast-forwarded)"),
        (f"llm: user answers/s, {n} batched", ua["batched"], "answers/s", "", f"({answers} answers, scripted always-ask)"),
        (f"llm: user answers/s, {n} episodes, answered in the step", ua["in_step"], "answers/s", "", ""),
        ("llm: user answers/s, one episode at a time", ua["single"], "answers/s", "",
         "same replies in all three" if same else "REPLIES DIFFER"),
        ("llm: user batched / one episode at a time", ua["batched"] / ua["single"], "ratio", "", ""),
        ("llm: user batched / answered in the step", ua["batched"] / ua["in_step"], "ratio", "", ""),
    ]


def one_row(model: str, dtype: str = "auto", threads: int | None = None, steps: int = 50, rounds: int = 3) -> list:
    """What one user waits for: decoding tokens/s at batch 1 (the planner's first prompt, `decode_speed`,
    best of `rounds`), then one planner episode (juan, eggs, seed 0, offline user, `steps` steps) run as a
    user runs it, `adapt rollout --agent planner --model DIR --max-steps 50`, in a process of its own:
    whole-process wall time (imports, model load, grammars, every step), with the load average before
    and after (the machine is shared: absolute figures are only as quiet as it was)."""
    import json
    import os
    import subprocess

    from adaptbench.compiler import load_domain
    from adaptbench.llm.cpu import cpu_defaults
    from adaptbench.llm.hf import TransformersBackend

    domain = load_domain(SPEC)
    s = cpu_defaults(model, batch=1)
    dtype = s.dtype if dtype == "auto" else dtype
    backend = TransformersBackend(model, dtype=dtype, batch_size=1, threads=threads or s.threads)
    con, unc = decode_speed(domain, backend, 1, rounds)
    rows = [(f"llm: settings: cpu {dtype}, {torch_threads()} torch threads, batch 1", weight_bytes_mb(model), "MB", "",
             f"(model {model})"),
            ("llm: constrained decoding tokens/s (batch 1)", con, "tok/s", ">= 25", "(forced tokens count; prompt apart)"),
            ("llm: unconstrained decoding tokens/s (batch 1)", unc, "tok/s", ">= 25", "(every token a forward pass)")]
    del backend
    out = Path(tempfile.mkdtemp()) / "episode.jsonl"
    cmd = [sys.executable, "-m", "adaptbench.cli", "rollout", "--agent", "planner", "--model", model,
           "--personas", "juan", "--tasks", "eggs", "--seeds", "0", "--max-steps", str(steps), "--out", str(out),
           "--quiet"] + ([] if dtype == s.dtype else ["--dtype", dtype])
    load = os.getloadavg()[0]
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t
    rec = json.loads(out.read_text().splitlines()[-1])
    st = [x.get("stats", {}) for x in rec["steps"]]
    read = sum(x.get("read_seconds", 0) for x in st)
    model_s = sum(x.get("seconds", 0) for x in st)
    new = sum(x.get("prompt_tokens", 0) - x.get("cached_tokens", 0) for x in st)
    passes = sum(x.get("tokens", 0) - x.get("forced_tokens", 0) for x in st)
    return rows + [
        (f"llm: one {steps}-step planner episode, whole process", wall, "s", "< 90" if steps == 50 else "",
         f"(`adapt rollout`, {rec['agent_config'].get('dtype', '?')}; {len(st)} steps; load {load:.2f} before, "
         f"{os.getloadavg()[0]:.2f} after)"),
        ("llm: episode: prompt tokens read / seconds", new, "tokens", "", f"({read:.1f} s reading)"),
        ("llm: episode: tokens generated / decoding seconds", sum(x.get("tokens", 0) for x in st), "tokens", "",
         f"({model_s - read:.1f} s decoding; {passes} forward passes, {passes / max(model_s - read, 1e-9):.1f}/s)"),
        ("llm: episode: outside the model", wall - model_s, "s", "", "(start-up, simulator, prompts, grammars)"),
        ("llm: episode: actions", len({x["action"] for x in rec["steps"]}), "distinct", "",
         "first: " + " | ".join(x["action"] for x in rec["steps"][:3])),
    ]


def weight_bytes_mb(model: str) -> float:
    """Megabytes of the model's weight files."""
    from adaptbench.llm.cpu import weight_bytes

    return weight_bytes(model) / 2**20


def torch_threads() -> int:
    """Torch's intra-op threads now."""
    import torch

    return torch.get_num_threads()


def main() -> int:
    """Run and print."""
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--model", help="model directory (default: build the tiny model in a temp dir)")
    p.add_argument("--quick", action="store_true", help="8 episodes of 5 steps, one round (a smoke run)")
    p.add_argument("--device", default="cpu", help="cpu (default), cuda, cuda:1, ... (the >= 4x target is a GPU one)")
    p.add_argument("--dtype", default="auto", help="auto (default: on a CPU, llm/cpu.py's choice by model size), "
                   "float32, bfloat16, float16")
    p.add_argument("--threads", type=int, help="torch threads on a CPU (default: llm/cpu.py's choice)")
    p.add_argument("--batches", default="1,16,64", help="batch sizes of the steps/s rows (default 1,16,64)")
    p.add_argument("--shape", choices=["smollm2"], help="build a random-weight model of this shape (SmolLM2-135M: "
                   "bench/model_shapes.py) into --model DIR, or a temp dir, and measure it")
    p.add_argument("--episode", action="store_true", help="with --model: tokens/s at batch 1 and one 50-step "
                   "planner episode as `adapt rollout` runs it (the CPU defaults for one episode; --dtype overrides)")
    p.add_argument("--steps", type=int, help="--episode: the episode's step budget (default 50); otherwise each "
                   "episode's steps in the steps/s rows (default: 3 quick, 2 quick for a real-sized model)")
    p.add_argument("--profile", metavar="FILE", help="also profile one rollout at the largest batch (operators "
                   "and Python functions) into FILE")
    p.add_argument("--passes", help="decoding passes to compare in the steps/s rows, e.g. hf,lean,graphs:1,graphs "
                   "(llm/batch_pass.py; ':N' decodes in N lanes, llm/lanes.py: graphs:1 has no overlap, graphs "
                   "alone overlaps two half-batches from 16 rows on CUDA; default: the device's own: graphs on a "
                   "GPU, hf on a CPU)")
    p.add_argument("--settings", action="store_true", help="with --model: steps/s under each backend setting "
                   "(threads, batch, session cache, budget, dtype; bench/llm_settings.py)")
    args = p.parse_args()
    if args.episode:
        if not args.model:
            p.error("--episode needs --model DIR")
        report(one_row(args.model, args.dtype, args.threads, args.steps or 50, 1 if args.quick else 3))
        return 0
    if args.settings:
        from adaptbench.compiler import load_domain
        from bench.llm_settings import run as settings

        if not args.model:
            p.error("--settings needs --model DIR")
        report(settings(load_domain(SPEC), args.model, args.quick))
        return 0
    if args.shape:
        from adaptbench.compiler import load_domain
        from bench.model_shapes import smollm2_shape

        args.model = str(smollm2_shape(load_domain(SPEC), args.model or Path(tempfile.mkdtemp()) / "smollm2"))
    batches = [int(b) for b in args.batches.split(",")]
    passes = tuple(args.passes.split(",")) if args.passes else (None,)
    report(run(args.model, args.quick, args.device, args.dtype, args.threads, batches, passes, args.steps,
               args.profile))
    return 0


if __name__ == "__main__":
    sys.exit(main())
