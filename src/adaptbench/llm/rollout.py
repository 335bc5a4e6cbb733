"""Batched rollouts of language-model agents: up to `batch` episodes advance together, one batched
generation for every episode awaiting an action, simulator steps (and user answers) in between; a
finished episode's slot is refilled from the queue. Records have the scripted agents' shape plus each
step's completion and statistics, and are appended to the same results file (resumable).

    policy = LLMPolicy(make_backend("transformers", model="models/tiny"), domain, "planner")
    res = rollout_llm(jobs, Path("runs/planner.jsonl"), domain, policy, batch=16)
"""

from __future__ import annotations

import traceback
from pathlib import Path

from ..harness.episode import targets
from ..harness.policy import Decision, Turn, View
from ..harness.record import RECORD_VERSION
from ..harness.results import ResultsFile, episode_key
from ..harness.rollout import RolloutResult, _write
from ..progress import Progress
from ..runtime.env import MAX_STEPS, Env


def made(env: Env) -> tuple:
    """The dishes made so far, as the progress line names them ("scrambled_eggs in pan_0 from egg_0")."""
    w = env.world
    out = []
    for eid, node in w.nodes.items():
        if node.verb is None or node.entity != eid:
            continue
        inputs = ", ".join(dict.fromkeys(n.name for n in node.inputs))
        out.append(f"{node.name} in {w.parent.get(eid)}" + (f" from {inputs}" if inputs else ""))
    return tuple(out)


class Running:
    """One episode in flight: its job, env, layout, the agent's history and the step records."""

    def __init__(self, job, env: Env, user=None):
        self.job, self.env, self.user = job, env, user
        self.id = f"{job.agent}/{job.persona}/{job.task}/{job.seed}"
        self.layout = env.reset()
        self.history: list = []
        self.steps: list = []
        self.error = None  # (message, traceback) when a step raised

    def view(self) -> View:
        """What the agent sees now."""
        e = self.env
        return View(self.id, e.task.id, e.task.text, self.layout, tuple(self.history), e.observed(), made(e),
                    e.world.step, e.max_steps)

    def apply(self, d: Decision) -> None:
        """Take the decided action and record the step."""
        r = self.env.step(d.action)
        self.history.append(Turn(d.action, r.observation, r.ok, r.reply))
        asked = targets(self.env)
        self.steps.append({"action": d.action, "ok": r.ok, "observation": r.observation, "reply": r.reply,
                           "completion": d.completion, **({"stats": d.stats} if d.stats else {}),
                           **({"targets": list(asked)} if asked is not None else {})})


def max_steps(policy) -> int:
    """The step budget: always-ask gets 1 + 1/N more steps (N: its question interval)."""
    every = policy.config().get("every")
    return int(MAX_STEPS * (1 + 1 / every)) if every else MAX_STEPS


def _error(ep: Running, config: dict, spec_hash: str) -> dict:
    j = ep.job
    return {"version": RECORD_VERSION, "agent": j.agent, "agent_config": config, "persona": j.persona,
            "task": j.task, "seed": j.seed, "spec_hash": spec_hash, "error": ep.error[0], "traceback": ep.error[1]}


def _record(ep: Running, config: dict, spec_hash: str) -> dict:
    ev = ep.env.evaluate()
    j = ep.job
    return {"version": RECORD_VERSION, "agent": j.agent, "agent_config": config, "persona": j.persona,
            "task": j.task, "seed": j.seed, "spec_hash": spec_hash, "scene": ep.env.scene.scene_id, "steps": ep.steps, "n_steps": len(ep.steps),
            "satisfied": ev.satisfied, "violated": ev.violated, **ev.as_dict()}


def run_batched(jobs, domain, policy, make_user, batch: int = 16, config: dict | None = None,
                steps: int | None = None):
    """Run the jobs, `batch` at a time; yields each finished episode's record. `make_user(domain,
    persona, task)` returns the episode's user (with `.bind(env)` if it reads the state); `config` is
    the agent configuration recorded (by default the policy's and the first user's); `steps` overrides
    the step budget (`max_steps(policy)`)."""
    queue = list(jobs)
    running: list = []
    while queue or running:
        while queue and len(running) < batch:
            job = queue.pop(0)
            persona, task = domain.persona[job.persona], domain.task[job.task]
            user = make_user(domain, persona, task)
            env = Env(domain, job.task, job.persona, job.seed, user=user,
                      max_steps=steps or max_steps(policy))
            if hasattr(user, "bind"):
                user.bind(env)
            ep = Running(job, env, user)
            policy.start(ep.id, env)
            running.append(ep)
        if config is None:
            config = {**policy.config(), **_user_config(running[0].user)}
        live = [ep for ep in running if not ep.env.done and ep.error is None]
        if live:
            for ep, d in zip(live, policy.act_batch([ep.view() for ep in live]), strict=True):
                try:
                    ep.apply(d if isinstance(d, Decision) else Decision(str(d)))
                except Exception as exc:  # noqa: BLE001 - one episode's bug must not end the run
                    ep.error = (f"{type(exc).__name__}: {exc}", traceback.format_exc())
        for ep in [ep for ep in running if ep.env.done or ep.error is not None]:
            running.remove(ep)
            getattr(policy, "end", lambda _e: None)(ep.id)
            yield _record(ep, config, domain.spec_hash) if ep.error is None else _error(ep, config, domain.spec_hash)


def _user_config(user) -> dict:
    return user.config() if hasattr(user, "config") else {"user": "offline"}


def rollout_llm(jobs, out: Path, domain, policy, make_user, batch: int = 16, progress: bool = True,
                user_config: dict | None = None, steps: int | None = None) -> RolloutResult:
    """Run the jobs not yet in `out` (same agent configuration and spec), appending each record."""
    res = RolloutResult()
    config = {**policy.config(), **(user_config or {"user": "offline"}), **({"max_steps": steps} if steps else {})}
    with ResultsFile.open(Path(out), domain.spec_hash) as store:
        def done(j) -> bool:
            return episode_key({"agent_config": config, "spec_hash": domain.spec_hash, "persona": j.persona,
                                "task": j.task, "seed": j.seed}) in store.done

        todo = [j for j in dict.fromkeys(jobs) if not done(j)]
        res.present = len(set(jobs)) - len(todo)
        bar = Progress(len(todo), f"rollout -> {Path(out).name}") if progress else None
        try:
            for record in run_batched(todo, domain, policy, make_user, batch, config, steps):
                _write(store, record, bar, res)
        finally:
            if bar:
                bar.__exit__(None, None, None)
    return res
