"""`Env`: one episode of a task for a persona in a scene — reset, step, evaluate."""

from __future__ import annotations

from dataclasses import dataclass

from ..compiler.model import CompiledDomain
from .actions import ActionFailed, bind, resolve_holders
from .effects import PRIMITIVES, dialogue, question
from .index import RuntimeIndex, runtime_index
from .observe import layout
from .scene import sample_scene
from .world import Event, World

MAX_STEPS = 50
REPEAT_LIMIT = 3  # the same action 3 times within the last 4 steps fails
REPEAT_WINDOW = 4


@dataclass(frozen=True)
class StepResult:
    """What one step returned."""

    observation: str
    ok: bool
    done: bool
    reply: str = ""


class Env:
    """An ADAPT episode. `persona` is an id or a `Persona`; `user` answers questions: a callable
    `(question, dialogue) -> str` or an object with `.answer(question, dialogue)`, where `dialogue` is
    the ((question, reply), ...) asked so far (`answerer` keeps the object as given, `user` its answering
    callable). `index` is the domain's runtime index (parser, preconditions); by default the one kept
    with the domain.

    Action text is read exactly as the grammar defines it (docs/grammar.md): canonical spelling, single
    spaces. Cleaning up model output ("Action:" prefixes, trailing dots) is the agent side's job
    (`adaptbench.agents.normalise`)."""

    def __init__(self, domain: CompiledDomain, task: str, persona: str | None = None, seed: int | None = 0,
                 full_scene: bool = False, user=None, max_steps: int = MAX_STEPS,
                 index: RuntimeIndex | None = None):
        if task not in domain.task:
            raise KeyError(f"unknown task '{task}' (tasks: {', '.join(domain.task)})")
        if isinstance(persona, str) and persona not in domain.persona:
            raise KeyError(f"unknown persona '{persona}' (personas: {', '.join(domain.persona)})")
        self.domain = domain
        self.task = domain.task[task]
        self.persona = domain.persona[persona] if isinstance(persona, str) else persona
        self.scene = sample_scene(domain, seed, full_scene)
        self.answerer = user
        self.user = getattr(user, "answer", user)
        self.max_steps = max_steps
        self.index = index if index is not None else runtime_index(domain)
        self.world: World = World(domain, self.scene)

    def reset(self) -> str:
        """Start the episode again on the same scene; returns the layout the agent starts with."""
        self.world = World(self.domain, self.scene)
        return layout(self.world)

    @property
    def done(self) -> bool:
        """Whether the episode has ended (Declare Done or the step limit)."""
        return self.world.done or self.world.step >= self.max_steps

    def step(self, text: str) -> StepResult:
        """Execute one action string; a failure is an observation, never an exception."""
        w = self.world
        if self.done:
            return StepResult("The episode is over.", False, True)
        w.step += 1
        ctx = {"user": self.user, "reply": ""}
        try:
            action, args, obs = self._run(text, ctx)
            ok = True
        except ActionFailed as exc:
            action, args, obs, ok = None, {}, str(exc), False
        w.settle()
        w.trace.append(Event(w.step, text, action, ok, obs, args, ctx["reply"]))
        return StepResult(obs, ok, self.done, ctx["reply"])

    def _run(self, text: str, ctx: dict):
        action, b = self._plan(text)
        obs = None
        for eff in action.effects:
            out = PRIMITIVES[eff.primitive](self.world, dict(eff.params), b, ctx)
            obs = out if out is not None else obs
        args = {k: str(v) for k, v in b.items()}
        return action.id, args, obs if obs is not None else _fill(action.success, b)

    def _plan(self, text: str):
        """The action and bindings `text` would run now, or ActionFailed (repeat limit, parse, bindings,
        preconditions). Changes nothing."""
        w = self.world
        recent = [e.text for e in w.trace[-(REPEAT_WINDOW - 1):]]
        if recent.count(text) >= REPEAT_LIMIT - 1:
            raise ActionFailed(f"You have tried '{text}' too many times in a row; try something else")
        parsed = self.index.parser.parse(text)
        if parsed is None:
            raise ActionFailed(_unknown_action(self.domain, text))
        action = self.domain.action[parsed.action]
        b = bind(w, action, parsed.args)
        resolve_holders(w, action, b)
        for check, fail in self.index.checks[action.id]:
            if not check(w, b):
                raise ActionFailed(_fill(fail, b))
        return action, b

    def pending_question(self, text: str):
        """What the user would be asked if `text` were stepped now: (question, dialogue), the arguments
        `user` would get, in the state it would see them in; None when the step would ask nothing (the
        episode is over, there is no user, the action fails, or it is not a question). Only an action
        whose first effect asks counts (nothing changes the world before the user reads it).
        Changes nothing: used to answer the questions of many episodes in one batch before stepping."""
        if self.done or self.user is None:
            return None
        try:
            action, b = self._plan(text)
        except ActionFailed:
            return None
        if not action.effects or action.effects[0].primitive != "ask":
            return None
        return question(dict(action.effects[0].params), b), dialogue(self.world)

    def observed(self):
        """What the agent has seen so far (a read-only snapshot): the entity ids it may name (layout,
        objects found, results made) and the content names it has seen."""
        from ..grammars.emit import Observed

        return Observed(frozenset(self.world.known), frozenset(self.world.known_contents))

    def seen(self):
        """The known part of the world, read-only (`runtime.seen.Seen`): what a scripted agent plans from."""
        from .seen import Seen

        return Seen(self.world)

    def evaluate(self):
        """Verdicts for the persona's preferences on the episode so far."""
        from .verify import evaluate

        return evaluate(self.domain, self.world, self.task, self.persona)


def _fill(template: str, b: dict) -> str:
    try:
        return template.format(**{k: str(v) for k, v in b.items()})
    except (KeyError, IndexError):
        return template


def _unknown_action(domain: CompiledDomain, text: str) -> str:
    import difflib

    examples = [a.example for a in domain.actions if a.example]
    close = difflib.get_close_matches(text, examples, n=1, cutoff=0.3)
    hint = f" (closest: '{close[0]}')" if close else ""
    return f"I don't understand '{text}'{hint}. Valid forms: " + "; ".join(
        f for a in domain.actions for f in a.forms)


def make_env(domain, persona: str, task: str, seed: int | None = 0, user=None, **options) -> Env:
    """The environment of (persona, task, seed) with the offline user answering questions (or `user`:
    a callable or an object with `answer`); `options` go to `Env` (`max_steps`, `full_scene`)."""
    from .users import OfflineUser

    if user is None:
        user = OfflineUser(domain, domain.persona[persona], domain.task[task])
    return Env(domain, task=task, persona=persona, seed=seed, user=user, **options)
