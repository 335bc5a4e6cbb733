"""Rollouts: run agents over personas x tasks x seeds, one JSON line per episode.

Results are appended as episodes finish, so a killed run loses nothing; running the same command
again skips the episodes already in the file.
"""

from __future__ import annotations

import json
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

from ..progress import Progress


@dataclass(frozen=True)
class Job:
    """One episode to run."""

    agent: str
    persona: str
    task: str
    seed: int

    @property
    def key(self) -> tuple:
        """Identity of the episode in a results file."""
        return (self.agent, self.persona, self.task, self.seed)


def parse_seeds(text: str) -> list:
    """'0-3' -> [0, 1, 2, 3]; '1,5,7' -> [1, 5, 7]."""
    out = []
    for part in text.split(","):
        if "-" in part:
            a, b = part.split("-")
            out.extend(range(int(a), int(b) + 1))
        elif part.strip():
            out.append(int(part))
    return out


def done_keys(path: Path) -> set:
    """Episodes already in a results file (a torn last line is ignored)."""
    keys = set()
    if not path.exists():
        return keys
    for line in path.read_text().splitlines():
        try:
            r = json.loads(line)
        except json.JSONDecodeError:
            continue
        keys.add((r["agent"], r["persona"], r["task"], r["seed"]))
    return keys


def drop_torn_tail(path: Path) -> None:
    """Cut a partial last line left by a killed run, so appends start on a fresh line."""
    if not path.exists():
        return
    data = path.read_bytes()
    if data and not data.endswith(b"\n"):
        path.write_bytes(data[: data.rfind(b"\n") + 1])


_DOMAIN = {}


def _init(spec: str) -> None:
    from ..compiler import load_domain

    _DOMAIN["d"] = load_domain(spec)


def run_episode(job: Job, spec: str = "spec") -> dict:
    """Run one episode with the offline user; return its record."""
    from ..agents.scripted import RUNNERS
    from ..agents.users import OfflineUser
    from ..runtime.env import Env

    if "d" not in _DOMAIN:
        _init(spec)
    d = _DOMAIN["d"]
    persona, task = d.persona[job.persona], d.task[job.task]
    env = Env(d, task=job.task, persona=job.persona, seed=job.seed, user=OfflineUser(d, persona, task))
    env.reset()
    RUNNERS[job.agent](env)
    ev = env.evaluate()
    steps = [{"action": e.text, "ok": e.ok, "observation": e.observation, "reply": e.reply} for e in env.world.trace]
    return {"agent": job.agent, "persona": job.persona, "task": job.task, "seed": job.seed,
            "scene": env.scene.scene_id, "spec_hash": d.spec_hash, "steps": steps, "n_steps": len(steps),
            "satisfied": ev.satisfied, "violated": ev.violated, **ev.as_dict()}


def rollout(jobs: list, out: Path, workers: int = 1, spec: str = "spec", progress: bool = True) -> int:
    """Run the jobs not yet in `out`, appending each result as it finishes; returns how many ran."""
    out.parent.mkdir(parents=True, exist_ok=True)
    drop_torn_tail(out)
    have = done_keys(out)
    todo = [j for j in jobs if j.key not in have]
    bar = Progress(len(todo), f"rollout -> {out.name}") if progress else None
    with open(out, "a", buffering=1) as f:
        if workers <= 1:
            for j in todo:
                _write(f, run_episode(j, spec), bar)
        else:
            with ProcessPoolExecutor(workers, initializer=_init, initargs=(spec,)) as pool:
                futures = [pool.submit(run_episode, j, spec) for j in todo]
                for fut in as_completed(futures):
                    _write(f, fut.result(), bar)
    if bar:
        bar.__exit__(None, None, None)
    return len(todo)


def _write(f, record: dict, bar) -> None:
    f.write(json.dumps(record) + "\n")
    f.flush()
    os.fsync(f.fileno())
    if bar:
        rate = record["satisfaction_rate"]
        bar.update(note=f"{record['agent']} {record['persona']}/{record['task']} "
                        f"{'n/a' if rate is None else f'{rate:.0%}'}")
