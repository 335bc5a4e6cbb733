"""Whether the student's action is as good as the teacher's, by the privileged oracle's own measure.

The scripted teacher carries out one plan in one order. When the student takes a step of that plan out of
order (it moves the eggs to the pan while the plan would fill the kettle first), a^t and a^s differ, and
Algorithm 1 would train the student away from a step that costs it nothing. An LLM teacher given the
student's history continues the student's own sub-recipe; the oracle needs telling. `outcome` plays the
episode on from its current state in a private copy (the episode's actions replayed on a fresh env of the
same scene, persona and user), first the given action, then the teacher's plan to the end; `as_good` says
whether the student's action ends at least as well (preferences satisfied and violated, components
completed) in no more steps, counted past the episode's budget. `Builder` skips such steps as `equivalent`
when `--skip-equivalent` is given (this project's option; the paper's teacher is an LLM and says nothing of it).

    outcome(episode, "Move egg_0 to pan_0", teacher.policy)  # Outcome(satisfied=3, violated=1, ...)
"""

from __future__ import annotations

from dataclasses import dataclass

from ..harness.episode import Episode
from ..harness.policy import Decision
from ..runtime.env import Env

EXTRA_STEPS = 100  # how far past the budget `outcome` plays on: more than any plan of the domain


@dataclass(frozen=True)
class Outcome:
    """How an episode ends when played on from a state: preferences satisfied and violated, task components
    completed, and the steps it took in all."""

    satisfied: int
    violated: int
    completed: int
    steps: int


def fork(episode: Episode, max_steps: int | None = None) -> Episode:
    """A private copy of a live `episode` in the same state (`training.replay` rebuilds a recorded one): a
    fresh env of the same scene, persona and user (and budget, or `max_steps`), with every action of the
    episode's history stepped again (the simulator and the offline user are deterministic). The copy keeps
    the episode's id, so a teacher's plan for it applies."""
    env = episode.env
    copy = Env(env.domain, env.task.id, env.persona, env.scene.seed, full_scene=env.scene.full, user=env.answerer,
               max_steps=env.max_steps if max_steps is None else max_steps, index=env.index)
    out = Episode(episode.id, copy)
    for turn in episode.history:
        out.apply(Decision(turn.action))
    return out


def outcome(episode: Episode, action: str, policy) -> Outcome:
    """The end of `episode` if `action` is taken now and the oracle `policy` (`OraclePolicy`, started on the
    episode) acts from then on, played past the episode's budget (by `EXTRA_STEPS` at most) so that a step
    wasted near the end still counts. `episode` itself is not changed."""
    ep = fork(episode, episode.env.max_steps + EXTRA_STEPS)
    ep.apply(Decision(action))
    while not ep.done:
        ep.apply(Decision(policy.next_step(ep.view())[0]))
    ev = ep.env.evaluate()
    return Outcome(ev.satisfied, ev.violated, len(ev.completed), ep.env.world.step)


def as_good(student: Outcome, teacher: Outcome) -> bool:
    """Whether the student's outcome is no worse than the teacher's on every count: at least as many
    preferences satisfied and components completed, no more violated, in no more steps."""
    return (student.satisfied >= teacher.satisfied and student.violated <= teacher.violated
            and student.completed >= teacher.completed and student.steps <= teacher.steps)


def equivalent(episode: Episode, student: str, teacher: str, policy) -> bool:
    """Whether the student's action `student` is as good as the teacher's `teacher` from `episode`'s state,
    each followed by the teacher's plan (`as_good` of their `outcome`s)."""
    return as_good(outcome(episode, student, policy), outcome(episode, teacher, policy))
