"""The base student's learning curve: behaviour cloning on the privileged oracle's full episodes (no
questions), evaluated at checkpoints on the split's unseen personas:

    adapt model curve --split 0 --sizes 128x4,256x4 --steps 300 --every 100 --episodes 32 --out DIR

1. Teacher data: the plain `oracle` on the split's training personas x the tasks, scene seeds from 100 up
   (`harness.seeds`), into OUT/data/oracle.jsonl (resumable, like `adapt rollout`).
2. For each size (hidden x layers): a tiny model (`llm.tiny.init_tiny`) trained by `training.pretrain`
   (one packed sequence per episode, the loss on every action); every `every` updates and after the last
   (and before the first with `initial`: slow, as a random model's episodes run to the budget), the model is saved to OUT/<size>/update-N and rolled out as the `planner` (greedy, the offline user,
   `max_steps` steps) on `episodes` episodes of the split's unseen personas x tasks x evaluation seeds 0-3
   (a fixed subset, the same at every checkpoint and size), into OUT/<size>/eval-N.jsonl.
3. OUT/curve.json: the settings, and per size and checkpoint the updates, the training loss, the share of
   dishes completed (task components made, over all episodes) and the mean satisfaction rate, each with its
   standard error; OUT/curve.png (the plots extra) draws both against updates.

Resumable after a kill at any point: the teacher rollouts skip the episodes written; each size's training
saves the trainer's state (model, optimizer, scheduler, RNG, step) to OUT/<size>/trainer/checkpoint-N at
every evaluation checkpoint (`training.pretrain`'s checkpoints) and resumes from the newest complete one, to
the same weights as an uninterrupted run; each checkpoint's point (update, loss since the previous one,
scores) is appended to OUT/<size>/points.jsonl once its evaluation is complete, and a point already there is
never evaluated again (a killed evaluation resumes its rollout file). A finished size is not trained again.
"""

from __future__ import annotations

import json
import random
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..harness.seeds import EVAL_SEEDS


@dataclass(frozen=True)
class CurveSettings:
    """What the learning curve trains and how it evaluates."""

    split: str = "0"
    seeds: tuple = tuple(range(100, 104))  # scene seeds of the oracle's episodes (never 0-3)
    sizes: tuple = ((128, 4), (256, 4))  # (hidden, layers) of each model
    steps: int = 300  # updates, one packed episode each
    every: int = 100  # evaluate every this many updates (and after the last)
    lr: float = 2e-3
    episodes: int = 32  # evaluation episodes (a fixed subset of unseen personas x tasks x eval seeds)
    eval_seeds: tuple = EVAL_SEEDS
    max_steps: int = 50
    batch: int = 16  # evaluation episodes stepped together
    vocab: int = 4096
    seed: int = 0  # initialisation, data order and the evaluation subset
    threads: int = 1
    workers: int = 1  # teacher rollout processes
    initial: bool = False  # also evaluate the untrained model (slow: every step fails, to the step budget)
    tasks: tuple = field(default=())  # empty: every task

    def size_name(self, size: tuple) -> str:
        """'h128-l4'."""
        return f"h{size[0]}-l{size[1]}"


def eval_jobs(domain, s: CurveSettings) -> list:
    """The evaluation episodes: `s.episodes` of the split's unseen personas x tasks x evaluation seeds,
    drawn with `s.seed` (all of them when there are fewer), in a stable order."""
    from ..harness.rollout import Job

    unseen = {str(k): v for k, v in domain.unseen.items()}[str(s.split)]
    tasks = s.tasks or tuple(domain.task)
    every = [Job("planner", p, t, seed) for seed in s.eval_seeds for p in unseen for t in tasks]
    if len(every) <= s.episodes:
        return every
    keep = set(random.Random(s.seed).sample(range(len(every)), s.episodes))
    return [j for i, j in enumerate(every) if i in keep]


def scores(domain, records) -> dict:
    """Dishes completed (task components made over components asked for, with the standard error of the
    per-episode share) and satisfaction (mean, standard error) of episode records (dicts)."""
    from ..harness.evaluate import mean_se

    made = [len(r.get("completed") or ()) / len(domain.task[r["task"]].components) for r in records]
    sat = [r["satisfaction_rate"] for r in records if r.get("satisfaction_rate") is not None]
    made_total = sum(len(r.get("completed") or ()) for r in records)
    asked_total = sum(len(domain.task[r["task"]].components) for r in records)
    m, se = mean_se(made)
    sm, sse = mean_se(sat)
    return {"episodes": len(records), "dishes": made_total, "dishes_of": asked_total, "dishes_rate": m,
            "dishes_se": se, "satisfaction": sm, "satisfaction_se": sse,
            "steps": sum(r.get("n_steps", 0) for r in records) / max(1, len(records))}


def evaluate(domain, model_dir: Path, jobs: list, out: Path, s: CurveSettings) -> dict:
    """Roll out the model in `model_dir` as the planner on `jobs` into `out` (episodes already there are
    kept) and score them."""
    from ..harness.rollout import rollout
    from ..llm.backend import make_backend

    backend = make_backend("transformers", model=str(model_dir), device="cpu", dtype="float32",
                           threads=s.threads, batch_size=s.batch)
    rollout(jobs, out, workers=1, progress=False, domain=domain, backend=backend, batch=s.batch,
            steps=s.max_steps)
    return scores(domain, _records(out))


def _records(path: Path) -> list:
    from .pretrain import read_records

    return read_records([path])


def oracle_data(domain, s: CurveSettings, out: Path, progress: bool = False) -> Path:
    """The oracle's episodes on the split's training personas into OUT/data/oracle.jsonl (resumable)."""
    from .student import StudentSettings, teacher_data

    st = StudentSettings(split=s.split, ask_seeds=(), oracle_seeds=tuple(s.seeds), workers=s.workers, tasks=s.tasks)
    return teacher_data(domain, st, out, progress)[0]


def train_size(domain, data: Path, size: tuple, s: CurveSettings, out: Path, jobs: list, log=print) -> dict:
    """Train one size with evaluations at checkpoints (resuming its training and keeping the points
    already in OUT/<size>/points.jsonl); its curve entry."""
    from ..llm.tiny import init_tiny
    from .pretrain import pretrain

    here = out / s.size_name(size)
    base = init_tiny(domain, here / "init", seed=s.seed, vocab_size=s.vocab, hidden=size[0], layers=size[1])
    points = read_points(here / "points.jsonl")

    def checkpoint(update: int, model, loss) -> None:
        from transformers import AutoTokenizer

        if update in points:
            return  # evaluated before a kill
        t0 = time.perf_counter()
        ck = here / f"update-{update}"
        model.save_pretrained(ck)
        AutoTokenizer.from_pretrained(base).save_pretrained(ck)
        sc = evaluate(domain, ck, jobs, here / f"eval-{update}.jsonl", s)
        add_point(here / "points.jsonl", points, {"update": update, "loss": loss, **sc,
                                                  "eval_seconds": round(time.perf_counter() - t0, 1)})
        log(f"{s.size_name(size)} update {update}: loss {loss if loss is None else round(loss, 3)}, dishes "
            f"{sc['dishes']}/{sc['dishes_of']}, satisfaction {sc['satisfaction'] or 0:.1%} "
            f"({points[update]['eval_seconds']:.0f} s)")

    if s.initial and 0 not in points:
        add_point(here / "points.jsonl", points,
                  {"update": 0, "loss": None, **evaluate(domain, base, jobs, here / "eval-0.jsonl", s)})
    r = pretrain(domain, base, [data], here / "final", steps=s.steps, lr=s.lr, seed=s.seed, threads=s.threads,
                 log=log, every=s.every, on_checkpoint=checkpoint, checkpoints=here / "trainer")
    entry = {"size": s.size_name(size), "hidden": size[0], "layers": size[1], "parameters": _parameters(base),
             "pretrain": asdict(r), "points": [points[u] for u in sorted(points) if u <= s.steps]}
    provenance = {"settings": asdict(s), "split": s.split, "scene_seeds": sorted(s.seeds), "teacher": "oracle",
                  "spec_hash": domain.spec_hash, "curve": entry}
    (here / "final" / "student.json").write_text(json.dumps(provenance, indent=1) + "\n")
    return entry


def read_points(path: Path) -> dict:
    """update -> point of a size's points.jsonl (a torn last line from a kill is ignored)."""
    points = {}
    if path.is_file():
        for line in path.read_text().splitlines():
            try:
                p = json.loads(line)
            except json.JSONDecodeError:
                continue
            points[p["update"]] = p
    return points


def add_point(path: Path, points: dict, point: dict) -> None:
    """Append one evaluated checkpoint to points.jsonl (flushed to disk) and to `points`."""
    import os

    torn = path.is_file() and path.stat().st_size and not path.read_bytes().endswith(b"\n")
    with path.open("a") as f:
        f.write(("\n" if torn else "") + json.dumps(point) + "\n")
        f.flush()
        os.fsync(f.fileno())
    points[point["update"]] = point


def _parameters(model_dir) -> int:
    from transformers import AutoModelForCausalLM

    return sum(p.numel() for p in AutoModelForCausalLM.from_pretrained(model_dir).parameters())


def learning_curve(domain, out, s: CurveSettings = CurveSettings(), log=print, progress: bool = False) -> dict:
    """Teacher data, then each size trained and evaluated; writes OUT/curve.json (and OUT/curve.png when
    matplotlib is installed) and returns the curve."""
    from .student import training_personas

    out = Path(out)
    t0 = time.perf_counter()
    data = oracle_data(domain, s, out, progress)
    jobs = eval_jobs(domain, s)
    curve = {"settings": asdict(s), "split": s.split, "training_personas": list(training_personas(domain, s.split)),
             "scene_seeds": sorted(s.seeds), "eval": [list(j.key[1:]) for j in jobs], "spec_hash": domain.spec_hash,
             "data_seconds": round(time.perf_counter() - t0, 1), "sizes": []}
    for size in s.sizes:
        curve["sizes"].append(train_size(domain, data, size, s, out, jobs, log))
        (out / "curve.json").write_text(json.dumps(curve, indent=1) + "\n")
    curve["seconds"] = round(time.perf_counter() - t0, 1)
    (out / "curve.json").write_text(json.dumps(curve, indent=1) + "\n")
    from ..harness.plots import PlotsUnavailable, draw_curve

    try:
        draw_curve(curve, out / "curve.png")
    except PlotsUnavailable as exc:
        log(f"no curve.png: {exc}")
    return curve
