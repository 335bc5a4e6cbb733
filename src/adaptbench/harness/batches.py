"""Batched rollouts of any `Policy` (scripted or language-model agents, the backend handed in with the
policy), on the harness's loop (`harness.episode.iter_batch`): the one rollout path. Up
to `batch` episodes advance together, one batched call (`Policy.act_batch`: for a model, one batched
generation) for every episode awaiting an action, then one batched generation per user backend for every episode whose action asks
the LLM user (`harness.episode.prepare_answers`, `LLMUser.prepare_answers`), then the simulator steps;
a finished episode's slot is refilled from the queue. Records are `EpisodeRecord`s with each step's
completion and statistics, appended to the same results file (resumable); an episode whose step raised
becomes an error record.

    policy = LLMPolicy(make_backend("transformers", model="models/tiny"), domain, "planner")
    res = rollout_policy(jobs, Path("runs/planner.jsonl"), domain, policy, make_user, batch=16)
    res = rollout_policy(jobs, out, domain, {"oracle": oracle, "never-ask": never}, make_user)  # several agents
"""

from __future__ import annotations

import traceback
from dataclasses import dataclass, field
from pathlib import Path

from ..runtime.env import MAX_STEPS, Env
from .episode import Episode, decide_each, iter_batch
from .policy import Policy
from .record import EpisodeRecord
from .results import ResultsFile, episode_key
from .workers import Interrupted, run_stream_pool


@dataclass
class RolloutResult:
    """What a rollout did: episodes run, already present, errors, and whether it was interrupted."""

    ran: int = 0
    present: int = 0
    errors: int = 0
    interrupted: bool = False
    error_samples: list = field(default_factory=list)


def max_steps(policy) -> int:
    """The step budget: always-ask gets 1 + 1/N more steps (N: its question interval)."""
    every = policy.config().get("every")
    return int(MAX_STEPS * (1 + 1 / every)) if every else MAX_STEPS


def episode_id(job) -> str:
    """The harness's id of a job's episode: agent/persona/task/seed."""
    return f"{job.agent}/{job.persona}/{job.task}/{job.seed}"


def record(ep: Episode, job, config: dict, spec_hash: str, notes: tuple = ()) -> dict:
    """A finished episode's record (its error record when a step, or evaluating it, raised), as a dict;
    `notes`: what the agent could not do on this task (scripted agents: `no recipe for component X`)."""
    header = {"agent": job.agent, "agent_config": config, "persona": job.persona, "task": job.task,
              "seed": job.seed, "spec_hash": spec_hash}
    if ep.error is not None:
        return EpisodeRecord(**header, error=ep.error[0], traceback=ep.error[1]).to_dict()
    try:
        ev = ep.env.evaluate()
        return EpisodeRecord(**header, scene=ep.env.scene.scene_id, steps=tuple(ep.steps), satisfied=ev.satisfied,
                             violated=ev.violated, preferences=tuple(ev.as_dict()["preferences"]),
                             satisfaction_rate=ev.satisfaction_rate, questions=ev.questions,
                             completed=tuple(ev.completed), notes=tuple(notes)).to_dict()
    except Exception as exc:  # noqa: BLE001 - one episode's bug must not end the run
        return EpisodeRecord(**header, error=f"{type(exc).__name__}: {exc}",
                             traceback=traceback.format_exc()).to_dict()


class _Same(dict):
    """A mapping that gives one value for every key it does not hold (one policy for every agent)."""

    def __init__(self, value):
        super().__init__()
        self.value = value

    def __missing__(self, key):
        return self.value


class ByAgent(Policy):
    """Several agents' policies as one: each episode goes to its agent's policy; each round, one
    `act_batch` per policy for its episodes (a policy that does not batch decides per episode, so that
    one episode's exception ends only that episode)."""

    name = "by-agent"

    def __init__(self):
        self.owner: dict = {}  # episode id -> (agent name, policy)

    def start(self, episode: str, env) -> None:
        """Start the episode on its agent's policy."""
        self.owner[episode][1].start(episode, env)

    def end(self, episode: str) -> None:
        """End the episode on its agent's policy."""
        _agent, policy = self.owner.pop(episode, (None, None))
        if policy is not None:
            policy.end(episode)

    def act(self, view):
        """The decision of the view's agent."""
        return self.owner[view.episode][1].act(view)

    def act_batch(self, views) -> list:
        """One call per policy for its views, answers in the order of `views`."""
        groups: dict = {}
        for i, v in enumerate(views):
            agent, policy = self.owner[v.episode]
            groups.setdefault(agent, (policy, []))[1].append(i)
        out = [None] * len(views)
        for policy, rows in groups.values():
            mine = [views[i] for i in rows]
            batched = type(policy).act_batch is not Policy.act_batch
            for i, d in zip(rows, policy.act_batch(mine) if batched else decide_each(policy, mine), strict=True):
                out[i] = d
        return out


def run_batched(jobs, domain, policy, make_user, batch: int = 16, config: dict | None = None,
                steps: int | None = None):
    """Run the jobs, `batch` at a time; yields each finished episode's record. `policy` is one Policy,
    or a dict agent name -> Policy for jobs of several agents. `make_user(domain, persona, task)`
    returns the episode's user (with `.bind(env)` if it reads the state); `config` is the agent
    configuration recorded (a dict agent -> configuration with several policies; by default
    `policy.config()` with the first user's); `steps` overrides the step budget (`max_steps(policy)`)."""
    pending: dict = {}  # episode id -> (job, user)
    several = isinstance(policy, dict)
    policies = policy if several else _Same(policy)
    configs = _Same(None if several else config)
    if several:
        configs.update(config or {})
    router = ByAgent() if several else policy

    def episodes():
        for job in jobs:
            persona, task = domain.persona[job.persona], domain.task[job.task]
            user = make_user(domain, persona, task)
            mine = policies[job.agent]
            env = Env(domain, job.task, job.persona, job.seed, user=user, max_steps=steps or max_steps(mine))
            if hasattr(user, "bind"):
                user.bind(env)
            pending[episode_id(job)] = (job, user)
            if several:
                router.owner[episode_id(job)] = (job.agent, mine)
            yield episode_id(job), env

    for ep in iter_batch(router, episodes(), batch, catch=True):
        job, user = pending.pop(ep.id)
        mine = policies[job.agent]
        if configs[job.agent] is None:
            configs[job.agent] = {**mine.config(), **_user_config(user)}
        yield record(ep, job, configs[job.agent], domain.spec_hash, _notes(mine, job))


def _notes(policy, job) -> tuple:
    notes = getattr(policy, "notes", None)
    return tuple(notes(job.task)) if notes is not None else ()


def _user_config(user) -> dict:
    return user.config() if hasattr(user, "config") else {"user": "offline"}


def rollout_policy(jobs, out: Path, domain, policy, make_user, batch: int = 16, progress: bool = True,
                   user_config: dict | None = None, steps: int | None = None, workers: int = 1) -> RolloutResult:
    """Run the jobs not yet in `out` (same agent configuration and spec), appending each record. `policy`
    is one Policy or a dict agent name -> Policy (scripted and model agents alike; a model policy holds
    its backend). The recorded configuration is the policy's `config()` with the user's (`user_config`)
    and any step budget.
    With `workers` > 1, that many forked processes (each with the parent's model, copy-on-write) run
    batched rollouts on jobs pulled from one queue and this process writes their records: data
    parallelism for models on the CPU."""
    res = RolloutResult()
    several = isinstance(policy, dict)
    configs = {a: {**p.config(), **(user_config or {"user": "offline"}), **({"max_steps": steps} if steps else {})}
               for a, p in (policy if several else {None: policy}).items()}
    config = configs if several else configs[None]
    with ResultsFile.open(Path(out), domain.spec_hash) as store:
        def done(j) -> bool:
            return episode_key({"agent_config": configs[j.agent if several else None], "spec_hash": domain.spec_hash,
                                "persona": j.persona, "task": j.task, "seed": j.seed}) in store.done

        todo = [j for j in dict.fromkeys(jobs) if not done(j)]
        res.present = len(set(jobs)) - len(todo)

        def work(js):
            return run_batched(js, domain, policy, make_user, batch, config, steps)

        write_all(store, run_stream_pool(todo, workers, work), len(todo), res, out, progress)
    return res


def write_all(store: ResultsFile, records, total: int, res: RolloutResult, out, progress: bool = True) -> None:
    """Append each record as it comes (duplicates skipped), with a progress bar over `total`; on
    `Interrupted` mark `res` and re-raise (what was written stays)."""
    from ..progress import progress_bar

    bar = progress_bar(total, f"rollout -> {Path(out).name}") if progress else None
    try:
        for record in records:
            _write(store, record, bar, res)
    except Interrupted:
        res.interrupted = True
        raise
    finally:
        if bar:
            bar.close()


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
        bar.set_postfix_str(f"{record['agent']} {record['persona']}/{record['task']} {note}", refresh=False)
        bar.update()
