"""The `Policy` interface: what an agent sees, and what it returns.

A policy is given a `View` of one episode — the task, the house layout, the history of its actions
with the observations and the user's replies, and what it may name (`observed`) — and returns its next
action as text. The harness (`harness.episode`) owns the loop: it calls `start` (privileged policies
may plan there), then `act` until the episode is over, then `end`; it steps the simulator (which asks
the user), records every step and hands the next `View` back. Batched policies (language models) implement
`act_batch` to choose for many episodes at once; `act_batch` defaults to calling `act` row by row.

    class Echo(Policy):
        name = "echo"
        def act(self, view: View) -> Decision:
            return Decision("Declare Done")
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Turn:
    """One step the agent took: its action, the simulator's observation, whether the action
    succeeded, and the user's reply when the action was a question."""

    action: str
    observation: str
    ok: bool
    reply: str = ""


@dataclass(frozen=True)
class View:
    """What the agent can see at one step of one episode (nothing from the simulator's internals).

    `observed` is the grammar's view of the state (`grammars.emit.Observed`): the entity ids the agent
    may name and the content names it has seen; a constrained decoder builds the state's grammar from
    it. `made` lists the dishes made so far, for the planner's progress line ("scrambled_eggs in pan_0
    from egg_0, butter"). `seen` is the known part of the world (`runtime.seen.Seen`: found entities,
    where they are, what they hold), valid for this step only: what scripted planners read instead of
    parsing the observations."""

    episode: str
    task: str
    task_text: str
    layout: str
    history: tuple = ()
    observed: object = None
    made: tuple = ()
    step: int = 0
    max_steps: int = 50
    seen: object = None


@dataclass(frozen=True)
class Decision:
    """A policy's answer: the action text, and for model policies what produced it (the prompt, the
    completion, token statistics), recorded with the step."""

    action: str
    prompt: object = None
    completion: str | None = None
    stats: dict = field(default_factory=dict)


class Policy(ABC):
    """Base class of every agent. Subclasses set `name` and implement `act` (batched policies also
    override `act_batch`)."""

    name = "policy"

    def config(self) -> dict:
        """The configuration recorded with each episode (what makes two runs comparable)."""
        return {"agent": self.name}

    def start(self, episode: str, env) -> None:
        """Called once when an episode starts. Privileged policies (the oracle, the teacher) may plan
        from `env` here; every other policy must ignore it."""
        return None  # noqa: B027 - most policies need no set-up

    def end(self, episode: str) -> None:
        """Called once when an episode has ended (Declare Done or the step limit): forget its state."""
        return None  # noqa: B027 - most policies keep no state

    @abstractmethod
    def act(self, view: View) -> Decision:
        """The next action for one episode."""

    def act_batch(self, views: Sequence[View]) -> list:
        """The next action for each of several episodes (one decision per view, in order)."""
        return [self.act(v) for v in views]
