"""The task probe (`adapt probe tasks`): does a model's first action follow the task it is given?

For each persona and scene seed, every task's step-0 planner prompt, and the privileged oracle's first
action of every task in that scene (for that persona: some plans start with the drink, some with the
food). The model scores each task's candidates under each task's prompt; a task is read right when its own
first action scores highest. The prompts of two tasks differ only in the task's line ("Make tea and eggs
for breakfast" against "Prepare tea and toast for breakfast"), so this asks the same thing of the task's
few tokens that the answer probe (`llm.probe`) asks of a reply's.

A model that ignores the task takes one action in every prompt of a scene. So it is right for the tasks
that share that first action, at most the largest such group: `ignoring` reports that ceiling.

    result = probe_tasks(backend_scorer(backend), domain, personas=("mark",), seeds=(0, 1, 2, 3))
    result.share, result.ignoring, result.by_task["tea_eggs"]
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

from ..agents.scripted import make_policy
from ..harness.episode import Episode
from ..runtime.env import Env
from .prompts import PromptBuilder


@dataclass(frozen=True)
class Scene:
    """One persona's scene: each task's step-0 prompt and its oracle's first action."""

    persona: str
    seed: int
    prompts: dict  # task -> Prompt
    firsts: dict  # task -> the oracle's first action

    @property
    def candidates(self) -> tuple:
        """The distinct first actions, in task order: what the model chooses among."""
        return tuple(dict.fromkeys(self.firsts.values()))

    @property
    def ignoring(self) -> int:
        """The most tasks a model that takes the same action in every prompt can read right."""
        return max(Counter(self.firsts.values()).values())


def _first(domain, oracle, task: str, persona: str, seed: int) -> tuple:
    """(step-0 view, the oracle's first action) of a task's episode."""
    ep = Episode(f"probe/{task}/{persona}/{seed}", Env(domain, task, domain.persona[persona], seed))
    oracle.start(ep.id, ep.env)
    try:
        view = ep.view()
        return view, oracle.act(view).action
    finally:
        oracle.end(ep.id)


def first_actions(domain, persona: str, seed: int, tasks) -> dict:
    """{task: the oracle's first action} in the scene of `seed` for `persona`."""
    oracle = make_policy("oracle", domain)
    return {t: _first(domain, oracle, t, persona, seed)[1] for t in tasks}


def scene(domain, persona: str, seed: int, tasks, builder: PromptBuilder) -> Scene:
    """The prompts and first actions of `tasks` for `persona` in the scene of `seed`."""
    oracle = make_policy("oracle", domain)
    steps = {t: _first(domain, oracle, t, persona, seed) for t in tasks}
    return Scene(persona, seed, {t: builder.prompt(view, made_after=()) for t, (view, _) in steps.items()},
                 {t: action for t, (_, action) in steps.items()})


@dataclass(frozen=True)
class TaskProbeResult:
    """How many (persona, seed, task) prompts a model read right, in all and by task, beside the most a
    model that ignores the task could."""

    prompts: int
    right: int
    ignoring_right: int
    by_task: dict  # task -> (right, prompts)
    chosen: dict  # task -> Counter of the actions the model preferred

    @property
    def share(self) -> float:
        """The share of prompts whose own first action scored highest."""
        return self.right / self.prompts if self.prompts else 0.0

    @property
    def ignoring(self) -> float:
        """The most a model that ignores the task can get."""
        return self.ignoring_right / self.prompts if self.prompts else 0.0

    def summary(self) -> dict:
        """The figures as JSON-ready values."""
        return {"prompts": self.prompts, "share": self.share, "ignoring_share": self.ignoring,
                "by_task": {t: {"right": r, "prompts": n, "chosen": dict(self.chosen[t])}
                            for t, (r, n) in self.by_task.items()}}


def probe_tasks(scorer, domain, personas, seeds, tasks=None, progress=None) -> TaskProbeResult:
    """Score every scene's candidates under each task's prompt (`scorer(prompt, actions) -> scores`, as
    `llm.probe.backend_scorer` makes); `progress(done, total)` after each scene."""
    tasks = list(tasks or domain.task)
    builder = PromptBuilder(domain, "planner")
    right, chosen, ignoring = Counter(), {t: Counter() for t in tasks}, 0
    scenes = [(p, s) for p in personas for s in seeds]
    for k, (persona, seed) in enumerate(scenes):
        sc = scene(domain, persona, seed, tasks, builder)
        ignoring += sc.ignoring
        for t in tasks:
            scores = scorer(sc.prompts[t], sc.candidates)
            best = sc.candidates[max(range(len(scores)), key=scores.__getitem__)]
            chosen[t][best] += 1
            right[t] += best == sc.firsts[t]
        if progress is not None:
            progress(k + 1, len(scenes))
    n = len(scenes)
    return TaskProbeResult(n * len(tasks), sum(right.values()), ignoring, {t: (right[t], n) for t in tasks}, chosen)
