"""The base student's cost: training speed and memory, rollout speed, and the reproduce pipeline's wall time.

    python bench/bench_student.py [--quick] [--threads 1]     # speed and memory rows (run_all.py runs --quick)
    python bench/bench_student.py --table [--out runs/bench-student] [--personas ...] [--seeds 0]

1. Training: updates per second and peak memory of `training.pretrain` (TRL's SFTTrainer, one whole oracle
   episode packed per update, one torch thread) for the base student's size 128x4 and for 256x4, each in a
   process of its own from a fresh `adapt model init` model, on real oracle episodes (split 0's training
   personas x tasks, scene seed 100). The first update is left out of the rate (allocation, warm-up); memory
   is the process's peak resident set (`resource.getrusage` maxrss: torch's tensors are invisible to
   tracemalloc) and how much it grew during training.
2. Rollout: steps per second of the shipped student (`--model student`) as the planner, greedy, offline user,
   on the CPU (1 torch thread, as `adapt rollout` uses), one episode at a time (batch 1) against 16 stepped
   together (batch 16), in this process; and `adapt rollout --model student --batch 16` on the same episodes as
   a user runs it, timed as a whole process (start, imports and loading included).
3. `adapt train reproduce --scale smoke`: its wall time, run once (not with --quick, which reports the
   pipeline's own estimate instead, beside the session scale's).

--table: the shipped student against the random tiny model it started from on split 0's unseen personas x
8 tasks x scene seed 0 (satisfaction, questions, failed steps, dishes; `adapt rollout` into OUT/<name>.jsonl,
resumable).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import ROOT, SPEC, report  # noqa: E402

SIZES = ((128, 4), (256, 4))  # the base student's size, and the next one the learning curve measured


# ------------------------------------------------------------------ training
def oracle_data(domain, out: Path, episodes: int) -> Path:
    """`episodes` oracle episodes on split 0's training personas x tasks, scene seed 100, into OUT."""
    from adaptbench.harness.rollout import Job, rollout
    from adaptbench.training.student import training_personas

    grid = [Job("oracle", p, t, 100) for p in training_personas(domain, "0") for t in domain.task]
    path = out / "oracle.jsonl"
    rollout(grid[::max(1, len(grid) // episodes)][:episodes], path, workers=1, progress=False, domain=domain)
    return path


def train_worker(hidden: int, layers: int, data: str, updates: int, work: str) -> dict:
    """In a fresh process: a new model of this size trained `updates` updates on `data`; seconds per update
    (the first left out), tokens per sequence, peak and training-time growth of the resident set (MB)."""
    import resource

    from adaptbench.compiler import load_domain
    from adaptbench.llm.tiny import init_tiny
    from adaptbench.training.pretrain import pretrain

    domain = load_domain(SPEC)
    init = init_tiny(domain, Path(work) / f"h{hidden}-l{layers}", hidden=hidden, layers=layers)
    stamps: list = []
    before = [0]

    def stamp(update, model, loss) -> None:
        stamps.append((time.perf_counter(), time.process_time()))

    def log(msg: str) -> None:
        if not before[0] and "sequences" in msg:  # the data is ready: what training adds comes after this
            before[0] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss

    r = pretrain(domain, init, [data], Path(work) / f"h{hidden}-l{layers}-out", steps=updates, lr=2e-3, threads=1,
                 log=log, every=1, on_checkpoint=stamp)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    n = max(1, len(stamps) - 1)
    wall, cpu = (stamps[-1][0] - stamps[0][0]) / n, (stamps[-1][1] - stamps[0][1]) / n
    params = sum(p.numel() for p in __import__("transformers").AutoModelForCausalLM.from_pretrained(init).parameters())
    return {"seconds_per_update": wall, "cpu_seconds_per_update": cpu, "timed_updates": len(stamps) - 1,
            "tokens_per_sequence": r.tokens / max(1, r.sequences), "sequences": r.sequences, "parameters": params,
            "peak_mb": peak / 1024, "growth_mb": (peak - before[0]) / 1024}


def _train_in_process(size: tuple, data: Path, updates: int, work: Path) -> dict:
    code = ("import json, sys; from bench.bench_student import train_worker; "
            f"print('RESULT ' + json.dumps(train_worker({size[0]}, {size[1]}, {str(data)!r}, {updates}, {str(work)!r})))")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, check=False)
    line = next((x for x in p.stdout.splitlines() if x.startswith("RESULT ")), None)
    if p.returncode or line is None:
        raise SystemExit(f"training h{size[0]}-l{size[1]} failed ({p.returncode}): {p.stderr.strip()[-2000:]}")
    return json.loads(line[len("RESULT "):])


def training_rows(domain, work: Path, quick: bool) -> list:
    """Updates per second and memory at each size, and the ratio of the two."""
    data = oracle_data(domain, work, 4 if quick else 16)
    updates = 4 if quick else 21
    got = {size: _train_in_process(size, data, updates, work) for size in SIZES}
    rows = []
    for (h, l_), r in got.items():
        note = (f"({r['parameters'] / 1e6:.2f}M parameters, {r['timed_updates']} updates of ~"
                f"{r['tokens_per_sequence']:.0f} tokens, 1 thread)")
        rows += [(f"student h{h}-l{l_}: training updates/s", 1 / r["seconds_per_update"], "upd/s", "", note),
                 (f"student h{h}-l{l_}: training CPU s/update", r["cpu_seconds_per_update"], "s", "",
                  "(this process's CPU time: the figure a quiet core's wall time approaches)"),
                 (f"student h{h}-l{l_}: training tokens/s", r["tokens_per_sequence"] / r["seconds_per_update"],
                  "tok/s", "", ""),
                 (f"student h{h}-l{l_}: training peak RSS", r["peak_mb"], "MB", "",
                  f"(+{r['growth_mb']:.0f} MB after the data was ready)")]
    (a, b) = (got[s] for s in SIZES)
    rows += [("student 256x4 / 128x4: CPU s per update", b["cpu_seconds_per_update"] / a["cpu_seconds_per_update"],
              "ratio", "", f"(parameters {b['parameters'] / a['parameters']:.2f}x; wall time "
              f"{b['seconds_per_update'] / a['seconds_per_update']:.2f}x)"),
             ("student 256x4 / 128x4: peak RSS", b["peak_mb"] / a["peak_mb"], "ratio", "", "")]
    return rows


# ------------------------------------------------------------------ rollouts
def _jobs(domain, n: int) -> list:
    from adaptbench.harness.rollout import Job

    unseen = [str(p) for p in {str(k): v for k, v in domain.unseen.items()}["0"]]
    return [Job("planner", p, t, 0) for p in unseen for t in domain.task][:n]


def _steps(path: Path) -> int:
    return sum(len(json.loads(x)["steps"]) for x in path.read_text().splitlines() if x.strip())


def rollout_rows(domain, work: Path, quick: bool, threads: int) -> list:
    """Steps per second of the shipped student at batch 1 and 16 in this process, and of `adapt rollout`."""
    from adaptbench.harness.rollout import rollout
    from adaptbench.llm.backend import make_backend
    from adaptbench.llm.named import named_path

    model = str(named_path("student"))
    n, steps = 16, (4 if quick else 20)
    jobs = _jobs(domain, n)
    rates, cpu = {}, {}
    for b in (1, 16):
        backend = make_backend("transformers", model=model, device="cpu", dtype="float32", threads=threads,
                               batch_size=b)
        path = work / f"student-b{b}.jsonl"
        t, c = time.perf_counter(), time.process_time()
        rollout(jobs, path, workers=1, progress=False, domain=domain, backend=backend, batch=b, steps=steps)
        rates[b], cpu[b] = _steps(path) / (time.perf_counter() - t), (time.process_time() - c) / _steps(path)
    path = work / "student-cli.jsonl"
    personas = ",".join(sorted({j.persona for j in jobs}))
    tasks = ",".join(sorted({j.task for j in jobs}))
    t, c = time.perf_counter(), _children_cpu()
    subprocess.run(["adapt", "rollout", "--agent", "planner", "--model", "student", "--personas", personas, "--tasks",
                    tasks, "--seeds", "0", "--max-steps", str(steps), "--batch", "16", "--out", str(path), "--quiet"],
                   check=True)
    whole, whole_cpu = time.perf_counter() - t, _children_cpu() - c
    done = _steps(path)
    where = f"({n} unseen episodes x <= {steps} steps, {threads} threads)"
    return [("student rollout steps/s, batch 1", rates[1], "steps/s", "", where),
            ("student rollout steps/s, batch 16", rates[16], "steps/s", "", where),
            ("student rollout CPU ms/step, batch 1", cpu[1] * 1e3, "ms", "", "(this process's CPU time)"),
            ("student rollout CPU ms/step, batch 16", cpu[16] * 1e3, "ms", "", ""),
            ("student rollout batch 16 / batch 1", rates[16] / rates[1], "ratio", "",
             f"(steps/s; in CPU time per step {cpu[1] / cpu[16]:.2f}x)"),
            ("adapt rollout --model student, whole process", whole, "s", "",
             f"({done} steps: {done / whole:.3g} steps/s with start-up and loading; {whole_cpu:.1f} CPU s)")]


def _children_cpu() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


# ------------------------------------------------------------------ reproduce
def reproduce_rows(domain, work: Path, quick: bool) -> list:
    """The smoke pipeline's wall time (run once, full mode only) and the estimates of both scales."""
    from adaptbench.training.pipeline import SCALES, makespan, stages

    plans = {k: stages(domain, "0", s, work / f"plan-{k}") for k, s in SCALES.items()}
    est = {k: makespan(plan, work / f"plan-{k}", jobs=2) for k, plan in plans.items()}
    rows = [(f"adapt train reproduce --scale {k}: estimate", sec, "s", "",
             f"(the pipeline's cost model, --jobs 2; in order {makespan(plans[k], work / f'plan-{k}') / 60:.0f} min)")
            for k, sec in est.items()]
    if not quick:
        t = time.perf_counter()
        subprocess.run(["adapt", "train", "reproduce", "--split", "0", "--scale", "smoke", "--out",
                        str(work / "reproduce")], check=True, stderr=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
        rows.insert(0, ("adapt train reproduce --scale smoke: wall time", time.perf_counter() - t, "s", "",
                        f"(estimate {est['smoke']:.0f} s)"))
    return rows


def run(quick: bool = False, threads: int = 1, each=None) -> list:
    """Measure and return report rows; `each(rows)` after each part (training, rollouts, reproduce)."""
    from adaptbench.compiler import load_domain

    domain = load_domain(SPEC)
    rows: list = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for part in (lambda: training_rows(domain, work, quick), lambda: rollout_rows(domain, work, quick, threads),
                     lambda: reproduce_rows(domain, work, quick)):
            got = part()
            rows += got
            if each:
                each(got)
    return rows


# ------------------------------------------------------------------ --table
def summary(path: Path, domain) -> dict:
    """Episodes, mean satisfaction (episodes with an applicable preference), questions, failed steps and
    dishes completed of one results file."""
    recs = [json.loads(x) for x in path.read_text().splitlines() if x.strip()]
    recs = [r for r in recs if "steps" in r and "error" not in r]
    rated = [r["satisfaction_rate"] for r in recs if r.get("satisfaction_rate") is not None]
    steps = [s for r in recs for s in r["steps"]]
    dishes = sum(len(domain.task[r["task"]].components) for r in recs)
    return {"episodes": len(recs), "satisfaction": sum(rated) / max(1, len(rated)),
            "questions": sum(r["questions"] for r in recs) / max(1, len(recs)),
            "asking_episodes": sum(1 for r in recs if r["questions"]), "steps": len(steps),
            "failed_steps": sum(1 for s in steps if not s["ok"]),
            "completed": sum(len(r["completed"]) for r in recs), "dishes": dishes}


def _rollout(model: str, out: Path, args) -> float:
    t0 = time.perf_counter()
    subprocess.run(["adapt", "rollout", "--agent", "planner", "--model", model, "--personas", args.personas,
                    "--tasks", "all", "--seeds", args.seeds, "--out", str(out), "--quiet"], check=True)
    return time.perf_counter() - t0


def table(args) -> int:
    """Run both rollouts (resuming) and print the quality table."""
    from adaptbench.compiler import load_domain

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if not (out / "tiny" / "config.json").is_file():
        subprocess.run(["adapt", "model", "init", "--out", str(out / "tiny")], check=True, stdout=subprocess.DEVNULL)
    domain = load_domain()
    print("| model | episodes | satisfaction | questions / episode | episodes that ask | failed steps | dishes "
          "completed | rollout s |\n|---|---|---|---|---|---|---|---|")
    for name, model in (("random tiny (adapt model init)", str(out / "tiny")), ("student", "student")):
        path = out / f"{'student' if model == 'student' else 'tiny'}.jsonl"
        secs = _rollout(model, path, args)
        s = summary(path, domain)
        print(f"| {name} | {s['episodes']} | {s['satisfaction']:.1%} | {s['questions']:.2f} | "
              f"{s['asking_episodes']} / {s['episodes']} | {s['failed_steps']} / {s['steps']} | "
              f"{s['completed']} / {s['dishes']} | {secs:.0f} |")
    return 0


def main(argv=None) -> int:
    """Speed and memory rows, or with --table the quality table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="a handful of updates and steps; the reproduce estimate only")
    p.add_argument("--threads", type=int, default=1,
                   help="torch threads of the in-process rollouts (default 1, as adapt rollout uses)")
    p.add_argument("--table", action="store_true", help="the quality table instead (shipped student vs random tiny)")
    p.add_argument("--out", default="runs/bench-student", help="--table: rollout directory")
    p.add_argument("--personas", default="leila,lisa,mark,samantha", help="--table: personas")
    p.add_argument("--seeds", default="0", help="--table: scene seeds")
    args = p.parse_args(argv)
    if args.table:
        return table(args)
    run(args.quick, args.threads, each=lambda rows: (report(rows), sys.stdout.flush()))  # each part when measured
    return 0


if __name__ == "__main__":
    sys.exit(main())
