"""A tiny student built by one command with fixed seeds: by default one that can ask (the checkpoint shipped
as `--model student` until 2026-11-27); with `--ask-seeds none`, a base student on the oracle alone, like the
one shipped now (built by `adapt model curve`, docs/training.md):

    adapt model student --out models/student

1. Teacher trajectories on the split's training personas (its unseen personas are never seen), all 8
   tasks: `oracle-ask` (the oracle's plan, asking first wherever that plan departs from the defaults) on
   `ask_seeds`, the plain `oracle` (no questions) on `oracle_seeds`; both from 100 up, apart from the
   evaluation seeds 0-3 (`harness.seeds`; the shipped checkpoint was built before, on seeds 1-6, and
   `adapt eval` flags its episodes on seeds 1-3). Written to OUT/data/*.jsonl (resumable, like `adapt rollout`).
2. A tiny model built locally (`llm.tiny.init_tiny`: a tokenizer trained on the domain's text, a random
   Llama from `seed`), or with `init` an existing model to continue from (e.g. the base student, taught
   to ask on top of what it cooks: `--init models/base --ask-seeds 100-103`).
3. `training.pretrain.pretrain` (TRL `SFTTrainer`, completion-only loss on the actions, prompts rendered
   with the planner prompt) into OUT, with OUT/student.json saying how it was made.

Resumable: run the same command again after a kill and the rollouts skip the episodes written, and the
pretraining resumes from its newest checkpoint in OUT/trainer (saved every `save_every` updates); a
finished build trains nothing again.
"""

from __future__ import annotations

import json
import platform
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class StudentSettings:
    """How the student is built (the defaults made the shipped checkpoint)."""

    split: str = "0"  # its unseen personas are left out of the data
    ask_seeds: tuple = tuple(range(100, 104))  # scene seeds of the oracle-ask episodes (never 0-3)
    oracle_seeds: tuple = tuple(range(104, 106))  # scene seeds of the plain oracle episodes
    pair_seeds: tuple = ()  # scene seeds of answer-following rows (`answer_rows`; none by default)
    said_seeds: tuple = ()  # scene seeds of templated-reply rows (`said_rows`: every option named; none by default)
    rows_context: str = "full"  # what of an answer row's prompt is trained on (`answer_rows.CONTEXTS`)
    accumulate: int = 1  # sequences an update (each weighs the same)
    hidden: int = 128
    layers: int = 4
    vocab: int = 4096
    words: str = "joined"  # how the new tokenizer splits text (`llm.tiny.WORD_SPLITS`); unused with `init`
    steps: int = 800  # updates, `accumulate` sequences (packed episodes or answer rows) each
    lr: float = 2e-3
    seed: int = 0  # model initialisation and data order
    workers: int = 2  # rollout processes
    save_every: int = 200  # a resumable checkpoint of the training (OUT/trainer) every this many updates
    tasks: tuple = field(default=())  # empty: every task
    init: str = ""  # a model directory to continue from (its tokenizer and weights); empty: a new tiny model
    device: str = "cpu"  # where the model trains (cpu; cuda on a GPU machine)

    def agents(self) -> tuple:
        """(agent, seeds) of the teacher trajectories (an agent with no seeds left out)."""
        return tuple((a, seeds) for a, seeds in (("oracle-ask", self.ask_seeds), ("oracle", self.oracle_seeds)) if seeds)


def training_personas(domain, split: str) -> tuple:
    """The personas of the domain that are not unseen in `split`; ValueError for an unknown split."""
    unseen = {str(k): v for k, v in domain.unseen.items()}
    if str(split) not in unseen:
        raise ValueError(f"unknown split '{split}' (choose from: {', '.join(unseen) or 'none'})")
    return tuple(p for p in domain.persona if p not in unseen[str(split)])


def teacher_data(domain, s: StudentSettings, out: Path, progress: bool = True) -> list:
    """Roll out the teachers into OUT/data/<agent>.jsonl (episodes already there are kept) and, with
    `pair_seeds`, write the answer rows to OUT/data/answer-rows.jsonl, with `said_seeds` the templated-reply
    rows to OUT/data/said-rows.jsonl (each kept when there); the files."""
    from ..harness.rollout import Job, rollout

    personas, tasks = training_personas(domain, s.split), s.tasks or tuple(domain.task)
    files = []
    from .answer_rows import answer_rows, said_rows, write_rows

    for seeds, name, build in ((s.pair_seeds, "answer-rows", lambda: answer_rows(domain, personas, s.pair_seeds,
                                                                                 tasks=list(s.tasks) or None)),
                               (s.said_seeds, "said-rows", lambda: said_rows(domain, s.said_seeds,
                                                                             tasks=list(s.tasks) or None))):
        if not seeds:
            continue
        path = out / "data" / f"{name}.jsonl"
        path.parent.mkdir(parents=True, exist_ok=True)
        if not path.is_file():
            write_rows(path, build())
        files.append(path)
    for agent, seeds in s.agents():
        path = out / "data" / f"{agent}.jsonl"
        path.parent.mkdir(parents=True, exist_ok=True)
        jobs = [Job(agent, p, t, seed) for seed in seeds for p in personas for t in tasks]
        rollout(jobs, path, workers=s.workers, progress=progress, domain=domain)
        files.append(path)
    return files


def build_student(domain, out, s: StudentSettings = StudentSettings(), log=print, progress: bool = True) -> dict:
    """Build the student into `out` (teacher data, a tiny model, TRL pretraining); returns and writes
    OUT/student.json: the settings, data, losses and seconds per stage."""
    from ..llm.tiny import init_tiny
    from .pretrain import pretrain

    out = Path(out)
    t0 = time.perf_counter()
    files = teacher_data(domain, s, out, progress)
    t_data = time.perf_counter() - t0
    base = Path(s.init) if s.init else init_tiny(domain, out / "init", seed=s.seed, vocab_size=s.vocab,
                                                  hidden=s.hidden, layers=s.layers, words=s.words)
    r = pretrain(domain, base, files, out, steps=s.steps, lr=s.lr, seed=s.seed, log=log, checkpoints=out / "trainer",
                 save_every=s.save_every, device=s.device, accumulate=s.accumulate, rows_context=s.rows_context)
    before = _init_info(s.init)
    seeds = {*s.ask_seeds, *s.oracle_seeds, *s.pair_seeds, *s.said_seeds, *before.get("scene_seeds", ())}
    info = {"settings": asdict(s), "split": s.split, "teachers": [a for a, _ in s.agents()], "scene_seeds": sorted(seeds),
            **({"init": before} if s.init else {}), "spec_hash": domain.spec_hash,
            "data": [str(f.relative_to(out)) for f in files],
            "pretrain": asdict(r), "seconds": {"data": round(t_data, 1), "pretrain": round(r.seconds, 1),
                                               "total": round(time.perf_counter() - t0, 1)},
            "machine": f"{platform.machine()}, " + ("torch 1 thread" if s.device == "cpu" else s.device)}
    (out / "student.json").write_text(json.dumps(info, indent=1) + "\n")
    return info


def _init_info(init: str) -> dict:
    """The student.json of the model continued from (its scene seeds count as trained on); {} without one."""
    try:
        return json.loads((Path(init) / "student.json").read_text()) if init else {}
    except (OSError, ValueError):
        return {}
