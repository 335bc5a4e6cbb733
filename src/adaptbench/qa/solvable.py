"""Solvability: for every persona x task on sampled scenes, the oracle must satisfy every applicable
preference. Anything it cannot is reported (a spec bug, or a preference that needs an availability
condition)."""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor

from ..progress import progress_bar

_DOMAINS: dict = {}


def _one(args) -> list:
    spec, digest, persona, task, seed = args
    from ..agents.scripted import play
    from ..compiler import load_domain
    from ..runtime.env import Env

    if (spec, digest) not in _DOMAINS:  # keyed by content too: the files at a path may change between calls
        _DOMAINS[(spec, digest)] = load_domain(spec)
    d = _DOMAINS[(spec, digest)]
    env = Env(d, task=task, persona=persona, seed=seed)
    env.reset()
    play("oracle", env)
    return [(persona, task, seed, v.id, v.reason) for v in env.evaluate().verdicts if v.verdict == "violated"]


def unsolved(spec: str, personas: list, tasks: list, seeds: list, workers: int = 1, progress: bool = True) -> list:
    """(persona, task, seed, preference, reason) for every applicable preference the oracle violates."""

    from ..compiler import spec_hash

    digest = spec_hash([spec])
    jobs = [(spec, digest, p, t, s) for p in personas for t in tasks for s in seeds]
    out = []
    with progress_bar(len(jobs), "check-solvable", enabled=progress) as bar:
        if workers <= 1:
            for j in jobs:
                out += _one(j)
                bar.update()
        else:
            with ProcessPoolExecutor(workers) as pool:
                for rows in pool.map(_one, jobs, chunksize=4):
                    out += rows
                    bar.update()
    return out
