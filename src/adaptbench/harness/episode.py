"""The episode loop: one runner drives any `Policy` against `Env` and records every step.

    ep = run_episode(policy, env, "oracle/juan/eggs/0")     # one episode, start to end
    eps = run_batch(policy, [(id1, env1), (id2, env2)])     # many at once: act_batch on the rows still running
    for ep in iter_batch(policy, envs(), width=16, catch=True): ...  # a stream, 16 at a time, slots refilled

For each step the runner builds the agent's `View` (task text, layout, history of `Turn`s, what it may
name, dishes made so far, step), asks the policy for a `Decision`, steps the simulator (which asks the
user when the action is a question) and records the step: action, observation, ok, reply, and for model
policies the decision's prompt, completion and token statistics; for a question, the preferences it targets.

Between the policy's decisions and the steps, `prepare_answers` lets users that answer in batches (the
language-model user) answer every question of the round in one call; each step then reads its prepared
answer, identical to the one it would have computed alone. Other users answer inside their step.
"""

from __future__ import annotations

import traceback
from dataclasses import dataclass

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
        self.error = None  # (message, traceback) when stepping raised (`iter_batch(catch=True)`)

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
    from ..runtime.users import question_targets

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
    envs = list(envs)
    if len({eid for eid, _ in envs}) != len(envs):
        raise ValueError("episode ids in one batch must be distinct")
    finished = {ep.id: ep for ep in iter_batch(policy, envs)}
    return [finished[eid] for eid, _ in envs]


def iter_batch(policy: Policy, envs, width: int | None = None, catch: bool = False, ticks: bool = False):
    """Run episodes together and yield each `Episode` as it finishes (in finishing order). `envs` is any
    iterable of (episode id, env), a generator included, drawn as slots free up: at most `width`
    episodes run at once (None: all). Each round `policy.act_batch` decides for every running episode
    in one call. With `catch`, an exception while stepping one episode's action ends that episode with
    `error` = (message, traceback) and the others go on; an exception from the policy ends the batch,
    and the policy forgets every episode still running. With `ticks`, each round also yields `Ticks(n)`
    (n: the steps it took), for a progress bar that moves while long episodes run."""
    if width is not None and width < 1:
        raise ValueError(f"batch width must be at least 1 (got {width})")
    source = iter(envs)
    running: list = []
    try:
        while True:
            _refill(policy, source, running, width, catch)
            over = [ep for ep in running if ep.done or ep.error is not None]
            if over:
                for ep in over:
                    running.remove(ep)
                    policy.end(ep.id)
                    yield ep
                continue
            if not running:
                return
            before = sum(len(ep.steps) for ep in running)
            _advance(policy, running, catch)
            if ticks:
                yield Ticks(sum(len(ep.steps) for ep in running) - before)
    finally:
        for ep in running:
            policy.end(ep.id)


@dataclass(frozen=True)
class Ticks:
    """Not an episode: `steps` steps were taken (progress for a bar; `iter_batch(ticks=True)`)."""

    steps: int


def _refill(policy: Policy, source, running: list, width: int | None, catch: bool = False) -> None:
    while width is None or len(running) < width:
        item = next(source, None)
        if item is None:
            return
        ep = Episode(*item)
        if any(other.id == ep.id for other in running):
            raise ValueError(f"episode ids in one batch must be distinct ('{ep.id}' is running)")
        running.append(ep)
        try:
            policy.start(ep.id, ep.env)
        except Exception as exc:
            if not catch:
                raise
            ep.error = _error(exc)


class Failed:
    """In place of a decision: the policy raised deciding for this episode (`decide_each`), which ends
    with `error` = (message, traceback)."""

    def __init__(self, exc: Exception):
        self.error = _error(exc)


def _error(exc: Exception) -> tuple:
    return (f"{type(exc).__name__}: {exc}", traceback.format_exc())


def decide_each(policy: Policy, views) -> list:
    """`policy.act` for each view, an exception becoming that view's `Failed`: how a policy that does not
    batch decides under `iter_batch(catch=True)`, so that one episode's bug ends only that episode."""
    out = []
    for view in views:
        try:
            out.append(policy.act(view))
        except Exception as exc:  # noqa: BLE001 - recorded as the episode's error
            out.append(Failed(exc))
    return out


def _decide(policy: Policy, running: list, catch: bool) -> list:
    views = [ep.view() for ep in running]
    if catch and type(policy).act_batch is Policy.act_batch:
        decisions = decide_each(policy, views)
    else:
        decisions = policy.act_batch(views)
    if len(decisions) != len(running):
        raise ValueError(f"{type(policy).__name__}.act_batch returned {len(decisions)} decisions "
                         f"for {len(running)} views")
    return [d if isinstance(d, Decision | Failed) else Decision(str(d)) for d in decisions]


def _advance(policy: Policy, running: list, catch: bool) -> None:
    decisions = _decide(policy, running, catch)
    for ep, d in zip(running, decisions, strict=True):
        if isinstance(d, Failed):
            ep.error = d.error
    steps = [(ep, d) for ep, d in zip(running, decisions, strict=True) if isinstance(d, Decision)]
    try:
        prepare_answers([(ep.env, d.action) for ep, d in steps])
    except Exception:
        if not catch:
            raise  # with `catch`, each user answers in its own step, where an error ends only that episode
    for ep, decision in steps:
        try:
            ep.apply(decision)
        except Exception as exc:
            if not catch:
                raise
            ep.error = _error(exc)


def prepare_answers(steps) -> None:
    """Before a round of steps: let users that answer in batches answer, together, every question about
    to be asked. `steps` is a list of (env, action text). A user batches when it has
    `prepare_answers(asks)` and `batch_key()`: the questions of users of one type with equal keys go to
    one `prepare_answers([(user, question, dialogue), ...])` call (on the first of them), which keeps
    each answer for that user's next `answer`. Other users (the offline one, plain callables) answer in
    their step as before; an action that would ask nothing (`Env.pending_question`) is left alone."""
    groups: dict = {}
    for env, action in steps:
        user = getattr(env, "answerer", None)
        if not hasattr(user, "prepare_answers"):
            continue
        pending = env.pending_question(action)
        if pending is not None:
            groups.setdefault((type(user), user.batch_key()), []).append((user, *pending))
    for asks in groups.values():
        asks[0][0].prepare_answers(asks)
