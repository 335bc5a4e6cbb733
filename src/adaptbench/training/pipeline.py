"""`adapt train reproduce`: the whole Reflection-DPO study as one resumable pipeline of stages.

    adapt train reproduce --split 0 --scale smoke --out runs/reproduce

This module only orders stages. Each stage is a typed config (`Stage`: its name, the `adapt` commands it
runs, the units its cost is counted in) and an artefact directory OUT/<stage>/; when every command of a
stage has succeeded, OUT/<stage>/done.json (the done-marker) records its commands and seconds. A run starts
at the first stage whose marker is missing or records other commands (another scale or split), so after a
kill at any point the same command goes on where it stopped: a killed stage is run again, and every
command underneath resumes by itself (rollouts skip finished episodes, `adapt train data` keeps the steps
written, trainers, the base student's pretraining included, resume from their last checkpoint and a
finished trainer is a no-op).

Stages, in order (S: the split; the evaluation personas are the split's unseen ones plus as many of its
training personas, scene seeds 0-3 or fewer; everything else trains on scene seeds from 100 up):

1. base: teacher data (the privileged `oracle`, no questions, on the split's training personas) and the
   base student behaviour-cloned on it (`adapt model student --ask-seeds none`: OUT/base/student.json).
   With `--base DIR`, an already trained base student instead (a model, its tokenizer and its
   student.json, e.g. `adapt model student` or `adapt model curve`'s OUT/<size>/final): checked (trained for
   this split, on no evaluation scene seed), recorded in OUT/base/done.json (path, weights' hash and its
   student.json) and used by every later stage; nothing is trained.
2. eval-base: evaluation rollouts of the base as planner, react, never-ask-llm and always-ask-llm (OUT/eval/base.jsonl).
3. pairs: Reflection-DPO's pairs from the base (`adapt train data`).
4. dpo, no-reflection, sft: the method and its ablations from the base (`adapt train ...`), each evaluated
   (OUT/eval/<method>.jsonl) as soon as it is trained, so a run stopped early still has every row it trained.
5. star-gate: the base's own rollouts on training personas, `adapt train star-gate` on them, its evaluation.
6. report: `adapt eval` (Table 1/2 and every method paired with the base planner on the same episodes:
   OUT/report/tables.md; the oracle's ceiling row is computed by `adapt eval` itself), the temporal figure and the questions figure (OUT/report/*.png).

With `jobs` > 1 (`--jobs`, default 2) stages that do not need each other (`Stage.after`) run side by side:
eval-base, pairs and star-gate after the base; dpo, no-reflection and sft after the pairs; the report last.

Before it starts, the pipeline prints its estimate: each stage's seconds from a cost model (`COSTS`:
seconds per unit of work, measured at smoke scale on 2 shared CPU cores, one torch thread) times its
units. The stages run as child processes of `python -m adaptbench.cli` in the pipeline's process group; on
Linux a child dies with the pipeline (a SIGKILL of the pipeline alone leaves no stage running).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from ..harness.seeds import EVAL_SEEDS

METHODS = ("dpo", "no-reflection", "sft")
BASE_AGENTS = ("planner", "react", "never-ask-llm", "always-ask-llm")  # the paper's prompted rows of Table 1


@dataclass(frozen=True)
class Scale:
    """The sizes of one pipeline run."""

    name: str
    hidden: int  # base student: hidden size
    layers: int
    base_updates: int  # behaviour-cloning updates, one oracle episode each
    teacher_seeds: str  # scene seeds of the oracle's episodes
    train_personas: int  # training personas the pairs and STaR-GATE rollouts use (0: all of the split's)
    tasks: tuple  # empty: every task
    pair_seeds: str  # scene seeds of `adapt train data` and the STaR-GATE rollouts
    max_steps: int  # step budget of every rollout (pairs, STaR-GATE, evaluation)
    train_steps: int  # optimizer steps of each trainer
    eval_personas: int  # unseen (and as many seen) personas evaluated (0: all)
    eval_seeds: str
    batch: int = 8
    base_lr: float = 2e-3  # behaviour-cloning learning rate
    trainer_args: tuple = ()  # extra `adapt train M` settings, the same for every method (dpo, ablations, STaR-GATE)
    dpo_args: tuple = ()  # extra settings of the preference trainers only (dpo, no-reflection)
    pair_args: tuple = ()  # extra `adapt train data` settings (the pairs stage)


SCALES = {
    "smoke": Scale("smoke", hidden=32, layers=1, base_updates=8, teacher_seeds="100", train_personas=1,
                   tasks=("toast_coffee",), pair_seeds="100", max_steps=6, train_steps=2, eval_personas=1,
                   eval_seeds="0", batch=4),
    # the base recipe measured by `adapt model curve` (docs/training.md): 128x4, 4,000 updates at lr 2e-3 on the
    # oracle's episodes of scene seeds 100-123 (2,304 episodes for a split of 12 training personas)
    "session": Scale("session", hidden=128, layers=4, base_updates=4000, teacher_seeds="100-123", train_personas=0,
                     tasks=(), pair_seeds="100", max_steps=50, train_steps=150, eval_personas=0, eval_seeds="0-3",
                     batch=16, base_lr=2e-3,
                     # the release's LoRA (rank 4 on q_proj, v_proj, lr 1e-4) is sized for a 70B model and barely moves
                     # the 1M base; rank 8 on every linear layer at lr 1e-3 collapsed DPO into search loops; at 3e-4 with
                     # the chosen action's NLL beside the DPO loss it held (docs/training.md, issue 28's first runs)
                     trainer_args=("--lr", "3e-4", "--lora-targets", "all-linear", "--lora-r", "8", "--lora-alpha", "16"),
                     dpo_args=("--loss", "sigmoid+sft"),
                     # a 1M student cannot write a reflection: the question is oracle-ask's at the choice a^t realises
                     # (the words a student taught on oracle-ask's episodes asks in; docs/training.md)
                     pair_args=("--questions", "choices")),
}

# Seconds per unit of work, per base-student size. Units: `start` a child process's start (importing torch and
# transformers), `trainer_start` a trainer's fixed cost (TRL, the dataset, saving the adapter and the merged
# model), `teacher_episode` an oracle episode, `update` a behaviour-cloning update of the base (one whole
# episode), `pair_step` a step of `adapt train data` (rollout, teacher, reflection, scoring), `train_step` an
# optimizer step of a trainer (LoRA, batch 4), `episode_step` a model's step in a batched rollout.
# h32-l1: measured by `--scale smoke` on 2 CPU cores shared with other jobs (load ~4; 2026-11-27).
# h128-l4: an update 1.0 s (measured on an idle core, one torch thread, the oracle's whole episodes of ~3.2k
# tokens; the learning curve's runs, 2026-11-27), a teacher episode 0.16 s (2,304 oracle episodes in ~6 min in one
# process); the rest from the shipped student's figures (docs/training.md's session run: 2,942 pair steps in
# 9 min on 2 workers, DPO 6.1 s/update, ~40 s per 2,560 evaluation steps, all at 20-step prompts), doubled where
# the cost grows with the prompt (50 steps: prompts ~2.5x longer). `train_step` measured by issue 28's session runs
# (2026-11-27, two splits at once, one core each): a DPO update 15-21 s at batch 4 (rank-8 LoRA on every linear
# layer, prompts of ~2,000 tokens). `pair_step` measured by the same runs: 1,860 pair steps in 1,137 s with the
# student's reflections (0.61 s), in ~565 s with `--questions choices` (0.30 s; the session scale's), most of it Δq/Δt scoring.
COSTS = {
    "h32-l1": {"start": 10.0, "trainer_start": 25.0, "teacher_episode": 0.3, "update": 1.5, "pair_step": 0.8,
               "train_step": 2.0, "episode_step": 0.35},
    "h128-l4": {"start": 10.0, "trainer_start": 25.0, "teacher_episode": 0.16, "update": 1.0, "pair_step": 0.35,
                "train_step": 18.0, "episode_step": 0.03},
}


@dataclass(frozen=True)
class Stage:
    """One stage: its name, the `adapt` commands it runs in order (argument lists), and its cost in units
    of `COSTS` (unit -> count)."""

    name: str
    commands: tuple
    units: tuple  # ((unit, count), ...)
    costs: str = "h32-l1"  # the row of COSTS
    given: dict | None = None  # what a stage with nothing to run records instead (`--base`: the base student)
    after: tuple | None = None  # the stages it needs done first (None: every stage before it)

    def marker(self, out: Path) -> Path:
        """The done-marker of this stage."""
        return out / self.name / "done.json"

    def done(self, out: Path) -> bool:
        """Whether a finished run of exactly these commands (and this given input) left its marker."""
        try:
            rec = json.loads(self.marker(out).read_text())
        except (OSError, ValueError):
            return False
        return rec.get("commands") == [list(c) for c in self.commands] and rec.get("given") == self.given


def cost_row(s: Scale) -> str:
    """The row of `COSTS` for the scale's base size: its own, else the measured size nearest in hidden x layers."""
    own = f"h{s.hidden}-l{s.layers}"
    if own in COSTS:
        return own

    def size(key):
        h, _, l_ = key[1:].partition("-l")
        return int(h) ** 2 * int(l_)

    return min(COSTS, key=lambda k: abs(size(k) - s.hidden ** 2 * s.layers))


def _personas(domain, split: str, s: Scale) -> tuple:
    from .student import training_personas

    train = training_personas(domain, split)
    unseen = tuple({str(k): v for k, v in domain.unseen.items()}[str(split)])
    n = s.eval_personas or len(unseen)
    evaluate = unseen[:n] + train[:n]
    return (train[:s.train_personas] if s.train_personas else train), evaluate


def _count(text: str) -> int:
    from ..harness.rollout import parse_seeds

    return len(parse_seeds(text))


class BadBase(ValueError):
    """`--base DIR` is not a base student this pipeline may use."""


def check_base(base, split: str) -> dict:
    """What the pipeline records of an already trained base student (`--base DIR`): its path, the hash of its
    weights and its student.json. BadBase (one line) when DIR lacks a model, tokenizer or student.json,
    was trained for another split, or on an evaluation scene seed."""

    from ..harness.seeds import eval_overlap, seeds_text

    d = Path(base).resolve()
    weights = sorted(d.glob("*.safetensors"))
    missing = [n for n, ok in (("config.json", (d / "config.json").is_file()), ("model weights (*.safetensors)", weights),
                               ("tokenizer_config.json", (d / "tokenizer_config.json").is_file()),
                               ("student.json", (d / "student.json").is_file())) if not ok]
    if missing:
        raise BadBase(f"--base {base}: no {', '.join(missing)} there (give the directory of a trained base student: "
                      "adapt model student --out DIR, or adapt model curve's OUT/<size>/final)")
    try:
        info = json.loads((d / "student.json").read_text())
    except ValueError as exc:
        raise BadBase(f"--base {base}: student.json is not JSON ({exc})") from None
    trained = info.get("split", (info.get("settings") or {}).get("split"))
    if str(trained) != str(split):
        raise BadBase(f"--base {base}: trained for split {trained}, not --split {split} (its data may hold that "
                      f"split's unseen personas): give a base trained with --split {split}")
    seeds = info.get("scene_seeds", _settings_seeds(info.get("settings") or {}))
    if not isinstance(seeds, list) or not seeds:
        raise BadBase(f"--base {base}: student.json records no scene_seeds, so its training may meet the evaluation "
                      "scenes: give a base built by adapt model student or adapt model curve")
    bad = eval_overlap(seeds)
    if bad:
        raise BadBase(f"--base {base}: trained on scene seed(s) {seeds_text(bad)}, which the evaluation uses "
                      f"({seeds_text(EVAL_SEEDS)}): give a base trained on seeds from 100 up")
    from .pretrain import file_sha256

    return {"base": str(d), "weights_sha256": [file_sha256(w) for w in weights], "student": info}


def _settings_seeds(settings: dict) -> list | None:
    """The scene seeds in a student.json's settings (one written before it recorded `scene_seeds`)."""
    keys = [k for k in ("ask_seeds", "oracle_seeds", "seeds") if k in settings]
    return sorted({int(x) for k in keys for x in settings[k]}) if keys else None


def stages(domain, split: str, s: Scale, out: Path, spec=None, base: dict | None = None) -> list:
    """The stages of the pipeline, in order. `base`: an already trained base student (`check_base`'s record)
    that the base stage records instead of training one."""
    from .student import training_personas

    out = Path(out)
    trainp, evalp = _personas(domain, split, s)
    tasks = s.tasks or tuple(domain.task)
    ntask, spec_args = len(tasks), (["--spec", str(spec)] if spec else [])
    tasks_arg = ",".join(tasks) if s.tasks else "all"
    common = [*spec_args, "--tasks", tasks_arg, "--max-steps", str(s.max_steps)]
    given, base, row = base, (base["base"] if base else str(out / "base")), cost_row(s)
    n_teacher = len(training_personas(domain, split)) * ntask * _count(s.teacher_seeds)
    n_pairs = len(trainp) * ntask * _count(s.pair_seeds)
    n_eval = len(evalp) * ntask * _count(s.eval_seeds)
    first = (Stage("base", (), (), given=given, after=()) if given else
             Stage("base", (("model", "student", *spec_args, "--out", base, "--split", split, "--ask-seeds", "none",
                             "--oracle-seeds", s.teacher_seeds, "--tasks", tasks_arg, "--hidden", str(s.hidden),
                             "--layers", str(s.layers), "--steps", str(s.base_updates), "--lr", str(s.base_lr),
                             "--workers", "1", "--quiet"),),
                   (("start", 1), ("teacher_episode", n_teacher), ("update", s.base_updates)), after=()))
    ev = out / "eval"
    where = [*common, "--personas", ",".join(evalp), "--seeds", s.eval_seeds, "--batch", str(s.batch), "--quiet"]
    n_steps = n_eval * s.max_steps  # evaluation steps of one agent (at most)
    result = [first,
              Stage("eval-base", (("rollout", "--agent", ",".join(BASE_AGENTS), "--model", base, *where,
                                   "--out", str(ev / "base.jsonl")),),
                    (("start", 1), ("episode_step", len(BASE_AGENTS) * n_steps)), after=("base",)),
              Stage("pairs", (("train", "data", *common, "--split", split, "--student", base, "--out",
                               str(out / "pairs"), "--personas", ",".join(trainp), "--seeds", s.pair_seeds,
                               "--batch", str(s.batch), "--workers", "1", *s.pair_args),),
                    (("start", 1), ("pair_step", n_pairs * s.max_steps)), after=("base",))]

    def evaluate(name: str, model) -> tuple:  # a method's evaluation rollouts, run as soon as it is trained
        return ("rollout", "--agent", "planner", "--model", str(model), *where, "--out", str(ev / f"{name}.jsonl"))

    for m in METHODS:
        result.append(Stage(m, (("train", m, "--data", str(out / "pairs"), "--model", base, "--out", str(out / m),
                                 "--max-steps", str(s.train_steps), "--threads", "1", *s.trainer_args,
                                 *(s.dpo_args if m != "sft" else ())), evaluate(m, out / m / "merged")),
                            (("start", 2), ("trainer_start", 1), ("train_step", s.train_steps),
                             ("episode_step", n_steps)), after=("pairs",)))
    rollouts = str(out / "star-gate" / "rollouts.jsonl")
    result.append(Stage("star-gate", (("rollout", "--agent", "planner", "--model", base, *common, "--personas",
                                       ",".join(trainp), "--seeds", s.pair_seeds, "--out", rollouts,
                                       "--batch", str(s.batch), "--quiet"),
                                      ("train", "star-gate", *spec_args, "--data", rollouts, "--model", base,
                                       "--out", str(out / "star-gate" / "model"), "--max-steps", str(s.train_steps),
                                       "--threads", "1", *s.trainer_args),
                                      evaluate("star-gate", out / "star-gate" / "model" / "merged")),
                        (("start", 3), ("trainer_start", 1), ("episode_step", n_pairs * s.max_steps + n_steps),
                         ("train_step", s.train_steps)), after=("base",)))
    rep = out / "report"
    files = [str(ev / f"{m}.jsonl") for m in ("base", *METHODS)]
    star = f"star-gate@{split}={ev / 'star-gate.jsonl'}"  # its rollouts' records name no split
    result.append(Stage("report", (("eval", *files, "--method", star, *spec_args, "--paired", "planner", "--markdown", str(rep / "tables.md"),
                                    "--plot-temporal", str(rep / "temporal.png"),
                                    "--plot-questions", str(rep / "questions.png")),),
                        (("start", 1),)))
    return [replace(st, costs=row) for st in result]


def stage_seconds(stage: Stage) -> float:
    """The cost model's seconds for one stage."""
    return sum(COSTS[stage.costs][u] * n for u, n in stage.units)


def needs(all_stages: list) -> dict:
    """Stage name -> the names of the stages it needs done first (`Stage.after`; None: all before it)."""
    names = [st.name for st in all_stages]
    return {st.name: set(names[:i] if st.after is None else st.after) for i, st in enumerate(all_stages)}


def makespan(all_stages: list, out: Path, jobs: int = 1) -> float:
    """The cost model's seconds for the stages not done, run `jobs` at a time as `run` schedules them (each
    stage, in order, as soon as a slot is free and the stages it needs are done)."""
    need, end, free = needs(all_stages), {}, [0.0] * max(1, jobs)
    for st in all_stages:
        ready = max((end.get(n, 0.0) for n in need[st.name]), default=0.0)
        if st.done(out):
            end[st.name] = ready
            continue
        slot = min(range(len(free)), key=lambda i: max(free[i], ready))
        end[st.name] = free[slot] = max(free[slot], ready) + stage_seconds(st)
    return max(end.values(), default=0.0)


def estimate_lines(all_stages: list, out: Path, jobs: int = 1) -> list:
    """The estimate printed before a run: one line per stage (done, or its seconds) and the total left
    (with `jobs` > 1, the time of the schedule that runs independent stages side by side)."""
    lines = []
    for st in all_stages:
        if st.done(out):
            lines.append(f"  {st.name:<14} done")
            continue
        lines.append(f"  {st.name:<14} ~{_duration(stage_seconds(st))}" + (f" (given: {st.given['base']})" if st.given else ""))
    at_once = f", {jobs} stages at a time" if jobs > 1 else ""
    return [f"estimate: ~{_duration(makespan(all_stages, out, jobs))} for the stages left (cost model of "
            f"training.pipeline, 2 CPU cores{at_once}):", *lines]


def _duration(sec: float) -> str:
    if sec < 120:
        return f"{sec:.0f} s"
    if sec < 7200:
        return f"{sec / 60:.0f} min"
    return f"{sec / 3600:.1f} h"


_LIVE: set = set()  # the stage commands running now (Popen), so that a Ctrl-C can stop them all
_LIVE_LOCK = threading.Lock()


def run_stage(stage: Stage, out: Path, log=print, runner=None) -> float:
    """Run a stage's commands (a failing one raises StageFailed) and write its done-marker; seconds."""
    (out / stage.name).mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    for cmd in stage.commands:
        argv = [sys.executable, "-m", "adaptbench.cli", *cmd] if runner is None else runner(cmd)
        log(f"$ adapt {' '.join(cmd)}")
        rc = _run_command(argv)
        if rc != 0:
            raise StageFailed(stage.name, cmd, rc)
    sec = time.perf_counter() - t0
    marker = stage.marker(out)
    tmp = marker.with_suffix(".tmp")
    tmp.write_text(json.dumps({"stage": stage.name, "commands": [list(c) for c in stage.commands],
                               "seconds": round(sec, 1), "estimate": round(stage_seconds(stage), 1),
                               "given": stage.given}, indent=1) + "\n")
    tmp.replace(marker)  # atomic: a kill leaves the marker whole or absent
    return sec


def _run_command(argv: list) -> int:
    """Run one stage command to its end; its exit status. A Ctrl-C while it runs stops it (`stop_children`)."""
    proc = subprocess.Popen(argv, env={**os.environ, "PYTHONUNBUFFERED": "1"}, preexec_fn=_die_with_parent)
    with _LIVE_LOCK:
        _LIVE.add(proc)
    try:
        return proc.wait()
    except KeyboardInterrupt:
        stop_children()
        raise
    finally:
        with _LIVE_LOCK:
            _LIVE.discard(proc)


def stop_children(grace: float = 2.0) -> None:
    """Stop every stage command still running: each has `grace` seconds to finish on the Ctrl-C it got with
    the pipeline (it writes what it has), then it is killed (its work resumes on the next run)."""
    with _LIVE_LOCK:
        procs = list(_LIVE)
    deadline = time.monotonic() + grace
    for p in procs:
        try:
            p.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def _die_with_parent() -> None:
    """In the child, before exec: on Linux, be killed when the pipeline process dies (SIGKILL included), so a
    rerun never meets an orphaned stage still writing its files."""
    try:
        import ctypes
        import signal

        ctypes.CDLL(None).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


class StageFailed(RuntimeError):
    """A stage's command exited with an error."""

    def __init__(self, stage: str, cmd, rc: int):
        super().__init__(f"stage {stage}: `adapt {' '.join(cmd)}` exited with {rc}")
        self.stage, self.rc = stage, rc


def run(all_stages: list, out: Path, log=print, runner=None, settings: dict | None = None, jobs: int = 1) -> dict:
    """Print the estimate, run every stage not done: in order, or with `jobs` > 1 up to `jobs` at a time, each
    as soon as the stages it needs are done (`Stage.after`). OUT/pipeline.json records the stages' seconds
    against their estimates. Returns that record. A failed stage lets the running ones finish, starts no new
    one, and is raised (StageFailed); a Ctrl-C stops every running stage (`stop_children`)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for line in estimate_lines(all_stages, out, jobs):
        log(line)
    t0 = time.perf_counter()
    if jobs > 1:
        _run_side_by_side(all_stages, out, log, runner, jobs)
    else:
        for st in all_stages:
            _start(st, out, log, runner)
    record = {"settings": settings or {}, "jobs": jobs,
              "stages": [json.loads(st.marker(out).read_text()) for st in all_stages],
              "seconds_now": round(time.perf_counter() - t0, 1)}
    (out / "pipeline.json").write_text(json.dumps(record, indent=1) + "\n")
    return record


def _start(st: Stage, out: Path, log, runner) -> None:
    """Run one stage (or note it done) and log it."""
    if st.done(out):
        log(f"stage {st.name}: done (skipped)")
        return
    if st.given:
        log(f"stage {st.name}: given ({st.given['base']}), nothing to run")
    else:
        log(f"stage {st.name}: running (~{_duration(stage_seconds(st))})")
    run_stage(st, out, log, runner)


def _run_side_by_side(all_stages: list, out: Path, log, runner, jobs: int) -> None:
    """`run` with up to `jobs` stages at a time (threads, each waiting on its stage's child process)."""
    need, done, waiting, running, failed = needs(all_stages), set(), list(all_stages), {}, []
    with ThreadPoolExecutor(jobs, thread_name_prefix="stage") as pool:
        try:
            while waiting or running:
                if not failed:
                    _launch_ready(waiting, running, done, need, jobs, lambda st: pool.submit(_start, st, out, log, runner),
                                  out, log)
                if not running:
                    break  # nothing left that can start (a stage failed)
                finished, _ = wait(running, timeout=0.5, return_when=FIRST_COMPLETED)
                for f in finished:
                    _collect(running.pop(f), f, running, done, failed, out, log)
        except KeyboardInterrupt:
            stop_children()
            raise
    if failed:
        raise failed[0]


def _launch_ready(waiting: list, running: dict, done: set, need: dict, jobs: int, submit, out: Path, log) -> None:
    """Start, in order, each waiting stage whose needs are done while a slot is free (a stage done before is
    noted at once)."""
    ready = [st for st in waiting if need[st.name] <= done]
    while ready:
        st = ready.pop(0)
        if st.done(out):
            waiting.remove(st)
            log(f"stage {st.name}: done (skipped)")
            done.add(st.name)  # the stages that need it may be ready now
            ready = [w for w in waiting if need[w.name] <= done]
        elif len(running) < jobs:
            waiting.remove(st)
            running[submit(st)] = st


def _collect(st: Stage, future, running: dict, done: set, failed: list, out: Path, log) -> None:
    """Record a finished stage: done (logged with its seconds), or its StageFailed kept for the end."""
    try:
        future.result()
    except StageFailed as exc:
        failed.append(exc)
        if running:
            log(f"stage {st.name} failed; waiting for {', '.join(r.name for r in running.values())} to finish "
                "(Ctrl-C stops them; a rerun resumes them)")
        return
    done.add(st.name)
    log(f"stage {st.name}: done in {_duration(json.loads(st.marker(out).read_text())['seconds'])}")


def scale_dict(s: Scale) -> dict:
    """The scale as JSON."""
    return asdict(s)


__all__ = ["COSTS", "EVAL_SEEDS", "SCALES", "BadBase", "Scale", "Stage", "StageFailed", "check_base", "estimate_lines",
           "makespan", "needs", "run", "stages", "stop_children"]
