"""Batched rollouts of any `Policy`, on the harness's loop (`harness.episode.iter_batch`): up
to `batch` episodes advance together, one batched generation (`LLMPolicy.act_batch`) for every episode
awaiting an action, then one batched generation per user backend for every episode whose action asks
the LLM user (`harness.episode.prepare_answers`, `LLMUser.prepare_answers`), then the simulator steps;
a finished episode's slot is refilled from the queue. Records are `EpisodeRecord`s with each step's
completion and statistics, appended to the same results file (resumable); an episode whose step raised
becomes an error record.

    policy = LLMPolicy(make_backend("transformers", model="models/tiny"), domain, "planner")
    res = rollout_policy(jobs, Path("runs/planner.jsonl"), domain, policy, make_user, batch=16)

The one rollout path: any `Policy` runs here, scripted or language-model (the backend handed in with the
policy), and several agents' policies at once (`policy` a dict by agent name, `byagent.ByAgent`):

    res = rollout_policy(jobs, out, domain, {"oracle": oracle, "never-ask": never}, OfflineUser)
"""

from __future__ import annotations

import traceback
from pathlib import Path

from ..harness.byagent import ByAgent, Same
from ..harness.episode import Episode, Ticks, iter_batch
from ..harness.output import RolloutResult, write_all
from ..harness.record import EpisodeRecord
from ..harness.results import ResultsFile, episode_key
from ..harness.workers import run_stream_pool
from ..runtime.env import MAX_STEPS, Env


def max_steps(policy, budget: int = MAX_STEPS) -> int:
    """The steps an episode of `policy` may take under the table's step budget `budget`: the budget
    itself, except that always-ask gets 1 + 1/N more steps (N: its question interval), so that its
    questions do not eat the steps of the task."""
    every = policy.config().get("every")
    return int(budget * (1 + 1 / every)) if every else budget


def episode_id(job) -> str:
    """The harness's id of a job's episode: agent/persona/task/seed."""
    return f"{job.agent}/{job.persona}/{job.task}/{job.seed}"


def record(ep: Episode, job, config: dict, spec_hash: str, notes: tuple = ()) -> dict:
    """A finished episode's record (its error record when a step raised), as a dict."""
    header = {"agent": job.agent, "agent_config": config, "persona": job.persona, "task": job.task,
              "seed": job.seed, "spec_hash": spec_hash}
    if ep.error is not None:
        return EpisodeRecord(**header, error=ep.error[0], traceback=ep.error[1]).to_dict()
    ev = ep.env.evaluate()
    return EpisodeRecord(**header, scene=ep.env.scene.scene_id, steps=tuple(ep.steps), satisfied=ev.satisfied,
                         violated=ev.violated, preferences=tuple(ev.as_dict()["preferences"]),
                         satisfaction_rate=ev.satisfaction_rate, questions=ev.questions,
                         completed=tuple(ev.completed), notes=tuple(notes)).to_dict()


def safe_record(ep: Episode, job, config: dict, spec_hash: str, notes: tuple = ()) -> dict:
    """`record`, with an exception while evaluating the episode turned into its error record."""
    try:
        return record(ep, job, config, spec_hash, notes)
    except Exception as exc:  # noqa: BLE001 - one episode's bug must not end the run
        return EpisodeRecord(agent=job.agent, agent_config=config, persona=job.persona, task=job.task, seed=job.seed,
                             spec_hash=spec_hash, error=f"{type(exc).__name__}: {exc}",
                             traceback=traceback.format_exc()).to_dict()


def run_batched(jobs, domain, policy, make_user, batch: int = 16, config: dict | None = None,
                steps: int | None = None, ticks: bool = False):
    """Run the jobs, `batch` at a time; yields each finished episode's record. `make_user(domain,
    persona, task)` returns the episode's user (with `.bind(env)` if it reads the state); `config` is
    the agent configuration recorded (by default `policy.config()` with the first user's); `steps` is
    the step budget (default 50; `max_steps(policy, steps)` per episode). With several agents, `policy` is a
    dict agent name -> Policy (and `config`, if given, a dict agent name -> configuration). With `ticks`,
    `Ticks(n)` items come between the records: n steps taken each round, and an episode's unused budget just
    before its record (so the ticks of a job add up to its budget, `step_budget`)."""
    pending: dict = {}  # episode id -> (job, user)
    policies, configs = _by_agent(policy, config)
    router = ByAgent(policies) if isinstance(policy, dict) else policy

    def episodes():
        for job in jobs:
            persona, task = domain.persona[job.persona], domain.task[job.task]
            user = make_user(domain, persona, task)
            env = Env(domain, job.task, job.persona, job.seed, user=user, max_steps=max_steps(policies[job.agent], steps or MAX_STEPS))
            if hasattr(user, "bind"):
                user.bind(env)
            pending[episode_id(job)] = (job, user)
            yield episode_id(job), env

    for ep in iter_batch(router, episodes(), batch, catch=True, ticks=ticks):
        if isinstance(ep, Ticks):
            if ep.steps:
                yield ep
            continue
        job, user = pending.pop(ep.id)
        if ticks and ep.env.max_steps > len(ep.steps):
            yield Ticks(ep.env.max_steps - len(ep.steps))
        if configs[job.agent] is None:
            configs[job.agent] = {**policies[job.agent].config(), **_user_config(user), "max_steps": steps or MAX_STEPS}
        yield safe_record(ep, job, configs[job.agent], domain.spec_hash, _notes(policies[job.agent], job))


def step_budget(jobs, policy, steps: int | None = None) -> int:
    """The steps the jobs may take in all (each its agent's `max_steps`, or `steps`): a progress bar's
    total when it moves by `Ticks`."""
    policies, _ = _by_agent(policy, None)
    return sum(max_steps(policies[j.agent], steps or MAX_STEPS) for j in jobs)


def _by_agent(policy, config) -> tuple:
    """(agent -> policy, agent -> configuration or None) for one policy or a dict of them."""
    if not isinstance(policy, dict):
        return Same(policy), config if isinstance(config, Same) else Same(config)
    configs = Same(None)
    configs.update(config or {})
    return policy, configs


def _notes(policy, job) -> tuple:
    notes = getattr(policy, "notes", None)
    return tuple(notes(job.task)) if notes is not None else ()


def _user_config(user) -> dict:
    return user.config() if hasattr(user, "config") else {"user": "offline"}


def rollout_policy(jobs, out: Path, domain, policy, make_user, batch: int = 16, progress: bool = True,
                   user_config: dict | None = None, steps: int | None = None, workers: int = 1) -> RolloutResult:
    """Run the jobs not yet in `out` (same agent configuration and spec), appending each record. The
    recorded configuration is `policy.config()` with the user's (`user_config`) and the step budget
    (`steps`, default 50: every record carries it, scripted agents' included).
    With `workers` > 1, that many forked processes (each with the parent's model, copy-on-write) run
    batched rollouts on jobs pulled from one queue and this process writes their records: data
    parallelism for models on the CPU. `policy` may be a dict agent name -> Policy (several agents, one
    configuration each)."""
    res = RolloutResult()
    config = _configs(policy, user_config, steps)
    with ResultsFile.open(Path(out), domain.spec_hash) as store:
        def done(j) -> bool:
            return episode_key({"agent_config": config[j.agent], "spec_hash": domain.spec_hash, "persona": j.persona,
                                "task": j.task, "seed": j.seed}) in store.done

        todo = [j for j in dict.fromkeys(jobs) if not done(j)]
        res.present = len(set(jobs)) - len(todo)

        def work(js):
            return run_batched(js, domain, policy, make_user, batch, config, steps, ticks=progress)

        total = step_budget(todo, policy, steps) if progress else len(todo)
        write_all(store, run_stream_pool(todo, workers, work), total, res, out, progress, unit="step")
    return res


def _configs(policy, user_config: dict | None, steps: int | None):
    """Agent name -> the configuration recorded: the policy's, the user's and the step budget."""
    def of(p) -> dict:
        return {**p.config(), **(user_config or {"user": "offline"}), "max_steps": steps or MAX_STEPS}

    if isinstance(policy, dict):
        return {agent: of(p) for agent, p in policy.items()}
    return Same(of(policy))
