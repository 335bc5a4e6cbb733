"""Rollouts: run agents over personas x tasks x seeds, one JSON line per episode.

Results are appended as episodes finish (see `results.py`: locked, append-only, each episode once),
so a killed run loses only the episodes in flight; running the same command again skips the episodes
of the same spec and agent configuration already in the file. Ctrl-C or SIGTERM stops the workers
at once and keeps everything finished; an exception in one episode becomes that episode's error
record and the run goes on.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .batches import rollout_policy
from .output import RolloutResult

__all__ = ["Job", "RolloutResult", "config_of", "done_keys", "parse_seeds", "rollout"]

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


def config_of(agent: str, max_steps: int = 50) -> dict:
    """The agent configuration recorded with each episode (scripted agents with the offline user, at the
    step budget `max_steps`)."""
    return {"agent": agent, "user": "offline", "max_steps": max_steps}


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


def rollout(jobs: list, out: Path, workers: int = 1, spec=None, progress: bool = True, *, domain=None,
            backend=None, make_user=None, user_config: dict | None = None, batch: int = 1,
            steps: int | None = None, **agent_options) -> RolloutResult:
    """Run the jobs not yet in `out`, appending each record as it finishes, for agents of any kind named
    in the registry (`harness.registry`): each agent's policy is made once (model agents get `backend`
    and `agent_options`, e.g. `budget`) and every episode runs on the batch runner
    (`batches.rollout_policy`), `batch` episodes at a time on each of `workers` forked processes. The
    user defaults to the offline one. Raises ResultsError (bad --out, locked, disk full) and Interrupted
    (Ctrl-C, SIGTERM) with the finished episodes kept."""
    from ..compiler import load_domain
    from ..runtime.users import OfflineUser
    from .registry import make

    domain = domain if domain is not None else load_domain(spec)  # loaded fresh: the files may have changed
    policies = {a: make(a, domain, backend=backend, **agent_options) for a in dict.fromkeys(j.agent for j in jobs)}
    return rollout_policy(list(jobs), Path(out), domain, policies, make_user or OfflineUser, batch, progress,
                          user_config, steps, workers)
