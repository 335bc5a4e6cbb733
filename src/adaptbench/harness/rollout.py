"""Rollouts: run agents over personas x tasks x seeds, one JSON line per episode.

Results are appended as episodes finish (see `results.py`: locked, append-only, each episode once),
so a killed run loses only the episodes in flight; running the same command again skips the episodes
of the same spec and agent configuration already in the file. Ctrl-C or SIGTERM stops the workers
at once and keeps everything finished; an exception in one episode becomes that episode's error
record and the run goes on.
"""

from __future__ import annotations

import traceback
from dataclasses import dataclass, field
from pathlib import Path

from ..progress import Progress
from .record import EpisodeRecord
from .results import ResultsFile, episode_key
from .workers import Interrupted, run_pool

MAX_SEEDS = 1_000_000


@dataclass(frozen=True)
class Job:
    """One episode to run."""

    agent: str
    persona: str
    task: str
    seed: int

    @property
    def key(self) -> tuple:
        """(agent, persona, task, seed): the episode within one spec and agent configuration."""
        return (self.agent, self.persona, self.task, self.seed)


@dataclass
class RolloutResult:
    """What a rollout did: episodes run, already present, errors, and whether it was interrupted."""

    ran: int = 0
    present: int = 0
    errors: int = 0
    interrupted: bool = False
    error_samples: list = field(default_factory=list)


def _seed_range(part: str) -> range:
    a, _, b = part.partition("-")
    lo, hi = int(a), int(b)
    if hi < lo:
        raise ValueError(f"empty seed range '{part}' ({hi} < {lo})")
    if hi - lo + 1 > MAX_SEEDS:
        raise ValueError(f"seed range '{part}' has {hi - lo + 1} seeds (at most {MAX_SEEDS:,})")
    return range(lo, hi + 1)


def parse_seeds(text: str) -> list:
    """'0-3' -> [0, 1, 2, 3]; '1,5,7' -> [1, 5, 7]; repeats dropped, order kept. ValueError when
    a part is not a number or a range, a range is empty or the total is absurd."""
    out: dict = {}
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        if not part.replace("-", "").isdigit() or part.count("-") > 1 or part.startswith("-"):
            raise ValueError(f"'{part}' is not a seed (a number >= 0) or a range such as 0-3")
        for s in (_seed_range(part) if "-" in part else [int(part)]):
            out[s] = None
        if len(out) > MAX_SEEDS:
            raise ValueError(f"more than {MAX_SEEDS:,} seeds")
    if not out:
        raise ValueError("no seeds given")
    return list(out)


def config_of(agent: str) -> dict:
    """The agent configuration recorded with each episode (scripted agents with the offline user)."""
    return {"agent": agent, "user": "offline"}


def done_keys(path: Path, spec_hash: str | None = None) -> set:
    """(agent, persona, task, seed) of the episodes in a results file (of one spec if given)."""
    keys = set()
    if not Path(path).exists():
        return keys
    from .results import iter_lines, parse_line

    for _, line in iter_lines(Path(path)):
        r, _why = parse_line(line)
        if r is not None and (spec_hash is None or r.get("spec_hash") == spec_hash):
            keys.add((r["agent"], r["persona"], r["task"], r["seed"]))
    return keys


_DOMAIN: dict = {}  # the domain this process runs, with the spec it was loaded from and its policies


def _init(spec: str, fresh: bool = False) -> None:
    """Load the domain of `spec` in this process, unless it is the one already loaded (`fresh`: load
    it again, as each rollout does: the files may have changed since)."""
    from ..compiler import load_domain

    if fresh or _DOMAIN.get("spec") != spec:
        _DOMAIN.clear()
        _DOMAIN.update(d=load_domain(spec), spec=spec, policies={})


def _policy(agent: str):
    from ..agents.scripted import make_policy

    policies = _DOMAIN["policies"]
    if agent not in policies:
        policies[agent] = make_policy(agent, _DOMAIN["d"])
    return policies[agent]


def _header(job: Job, spec_hash: str | None) -> dict:
    return {"agent": job.agent, "agent_config": config_of(job.agent), "persona": job.persona,
            "task": job.task, "seed": job.seed, "spec_hash": spec_hash}


def run_episode(job: Job, spec: str = "spec") -> dict:
    """Run one episode with the offline user through the harness's loop; return its record (as a dict)."""
    from ..agents.users import OfflineUser
    from ..runtime.env import Env
    from .episode import run_episode as run

    _init(spec)
    d = _DOMAIN["d"]
    persona = d.persona[job.persona]
    env = Env(d, task=job.task, persona=job.persona, seed=job.seed, user=OfflineUser(d, persona, d.task[job.task]))
    ep = run(_policy(job.agent), env, f"{job.agent}/{job.persona}/{job.task}/{job.seed}")
    ev = env.evaluate()
    record = EpisodeRecord(**_header(job, d.spec_hash), scene=env.scene.scene_id, steps=tuple(ep.steps),
                           satisfied=ev.satisfied, violated=ev.violated,
                           preferences=tuple(ev.as_dict()["preferences"]),
                           satisfaction_rate=ev.satisfaction_rate, questions=ev.questions,
                           completed=tuple(ev.completed), notes=tuple(_notes(d, env.task)))
    return record.to_dict()


def _notes(domain, task) -> list:
    """What the scripted agents could not do on this task (`no recipe for component X`)."""
    from ..agents.plans import notes

    return notes(domain, task)


def safe_episode(job: Job, spec: str = "spec") -> dict:
    """`run_episode`, with an exception turned into the episode's error record (traceback included)."""
    try:
        return run_episode(job, spec)
    except Exception as exc:  # noqa: BLE001 - one episode's bug must not end the run
        spec_hash = _DOMAIN["d"].spec_hash if _DOMAIN.get("spec") == spec else None
        return EpisodeRecord(**_header(job, spec_hash), error=f"{type(exc).__name__}: {exc}",
                             traceback=traceback.format_exc()).to_dict()


def rollout(jobs: list, out: Path, workers: int = 1, spec: str = "spec", progress: bool = True) -> RolloutResult:
    """Run the jobs not yet in `out`, appending each result as it finishes. Raises ResultsError (bad
    --out, locked, disk full) and Interrupted (Ctrl-C, SIGTERM) with the finished episodes kept."""
    _init(spec, fresh=True)  # workers are forked after this and keep this domain
    spec_hash = _DOMAIN["d"].spec_hash
    jobs = list(dict.fromkeys(jobs))
    res = RolloutResult()
    with ResultsFile.open(Path(out), spec_hash) as store:
        todo = [j for j in jobs if episode_key(_header(j, spec_hash)) not in store.done]
        res.present = len(jobs) - len(todo)
        write_all(store, run_pool(todo, spec, workers), len(todo), res, out, progress)
    return res


def write_all(store: ResultsFile, records, total: int, res: RolloutResult, out, progress: bool = True) -> None:
    """Append each record as it comes (duplicates skipped), with a progress bar over `total`; on
    `Interrupted` mark `res` and re-raise (what was written stays)."""
    bar = Progress(total, f"rollout -> {Path(out).name}") if progress else None
    try:
        for record in records:
            _write(store, record, bar, res)
    except Interrupted:
        res.interrupted = True
        raise
    finally:
        if bar:
            bar.__exit__(None, None, None)


def _write(store: ResultsFile, record: dict, bar, res: RolloutResult) -> None:
    if not store.append(record):
        return
    res.ran += 1
    if "error" in record:
        res.errors += 1
        if len(res.error_samples) < 3:
            res.error_samples.append(f"{record['agent']} {record['persona']}/{record['task']} seed {record['seed']}: "
                                     f"{record['error']}")
    if bar:
        rate = record.get("satisfaction_rate")
        note = "error" if "error" in record else ("n/a" if rate is None else f"{rate:.0%}")
        bar.update(note=f"{record['agent']} {record['persona']}/{record['task']} {note}")

