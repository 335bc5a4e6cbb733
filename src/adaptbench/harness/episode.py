"""The episode loop: one runner drives any `Policy` against `Env` and records every step.

    ep = run_episode(policy, env, "oracle/juan/eggs/0")     # one episode, start to end
    eps = run_batch(policy, [(id1, env1), (id2, env2)])     # many at once: act_batch on the rows still running

For each step the runner builds the agent's `View` (task text, layout, history of `Turn`s, what it may
name, dishes made so far, step), asks the policy for a `Decision`, steps the simulator (which asks the
user when the action is a question) and records the step: action, observation, ok, reply, and for model
policies the decision's prompt, completion and token statistics; for a question, the preferences it targets.
"""

from __future__ import annotations

from ..runtime.env import Env
from .policy import Decision, Policy, Turn, View
from .record import StepRecord


class Episode:
    """One running (or finished) episode: its env, id, layout, the agent's history and the step records."""

    def __init__(self, episode: str, env: Env):
        self.id, self.env = episode, env
        self.layout = env.reset()
        self.history: list = []
        self.steps: list = []

    @property
    def done(self) -> bool:
        """Whether the episode is over (Declare Done or the step limit)."""
        return self.env.done

    def view(self) -> View:
        """What the agent sees now."""
        env = self.env
        return View(self.id, env.task.id, env.task.text, self.layout, tuple(self.history), env.observed(),
                    made(env), env.world.step, env.max_steps, env.seen())

    def apply(self, decision: Decision) -> Turn:
        """Take the decided action; record the step and return the agent's turn."""
        result = self.env.step(decision.action)
        turn = Turn(decision.action, result.observation, result.ok, result.reply)
        self.history.append(turn)
        self.steps.append(StepRecord(decision.action, result.ok, result.observation, result.reply,
                                     decision.prompt, decision.completion, decision.stats or None,
                                     targets(self.env)))
        return turn


def targets(env: Env):
    """For a step that asked a question: the ids of the preferences it targets (the offline user's
    matcher: what the offline user answered from, the judge of any other user); None otherwise."""
    from ..agents.users import question_targets

    event = env.world.trace[-1] if env.world.trace else None
    if event is None or event.action != "ask" or not event.ok:
        return None
    return question_targets(env, event.args.get("question", ""))


def made(env: Env) -> tuple:
    """The dishes made so far, as the planner's progress line names them: 'NAME in HOLDER from A, B'
    (results of the agent's actions, as contents of a container or as objects), in the order made."""
    w = env.world
    found = [(node, holder) for holder, nodes in w.contents.items() for node in nodes if node.verb is not None]
    found += [(node, w.parent.get(eid)) for eid, node in w.nodes.items() if node.verb is not None]
    return tuple(_made_line(node, holder) for node, holder in sorted(found, key=lambda x: x[0].nid))


def _made_line(node, holder) -> str:
    inputs = ", ".join(dict.fromkeys(n.name for n in node.inputs))
    return f"{node.name} in {holder}" + (f" from {inputs}" if inputs else "")


def run_episode(policy: Policy, env: Env, episode: str = "episode") -> Episode:
    """Run one episode from reset to its end; `env` holds the final world (for `env.evaluate()`)."""
    return run_batch(policy, [(episode, env)])[0]


def run_batch(policy: Policy, envs: list) -> list:
    """Run several episodes at once: each round, `policy.act_batch` decides for every episode still
    running. `envs` is a list of (episode id, env); returns the finished `Episode`s in that order."""
    episodes = [Episode(eid, env) for eid, env in envs]
    if len({e.id for e in episodes}) != len(episodes):
        raise ValueError("episode ids in one batch must be distinct")
    running: list = []
    try:
        for ep in episodes:
            running.append(ep)
            policy.start(ep.id, ep.env)
        running = [ep for ep in episodes if not _finish(policy, ep)]
        while running:
            decisions = policy.act_batch([ep.view() for ep in running])
            if len(decisions) != len(running):
                raise ValueError(f"{type(policy).__name__}.act_batch returned {len(decisions)} decisions "
                                 f"for {len(running)} views")
            for ep, decision in zip(running, decisions, strict=True):
                ep.apply(decision if isinstance(decision, Decision) else Decision(str(decision)))
            running = [ep for ep in running if not _finish(policy, ep)]
    finally:  # an exception ends the batch: the policy forgets every episode still running
        for ep in running:
            policy.end(ep.id)
    return episodes


def _finish(policy: Policy, ep: Episode) -> bool:
    if ep.done:
        policy.end(ep.id)
        return True
    return False
