"""One ADAPT episode as the RL interfaces see it: the `Env` that `adapt rollout` builds (same scene seed,
offline user, verifiers), plus the episode's choice of persona, task and seed, and the step record every
interface returns (observation, success, parsed action, reply, reward, verdicts at the end).

    s = Session.open(domain, task="eggs", persona="juan", seed=0)
    first = s.opening()                     # task text and the house's layout
    out = s.step('Ask "How do you like your eggs?"')
    out.observation, out.reward, out.terminated, out.info["verdicts"]

Gymnasium (`envs.gym`), the HTTP server (`envs.server`), TRL's environment class (`envs.trl`) and the
`verifiers` entry point (`envs.verifiers_env`) are thin layers over this class.
"""

from __future__ import annotations

import numbers
import random
from typing import NamedTuple

from ..compiler.model import CompiledDomain
from ..runtime.env import MAX_STEPS, Env

REWARDS = ("final", "progress")
MAX_ACTION_CHARS = 2000  # longer action text fails as a step (no action of the grammar comes near it)


class Outcome(NamedTuple):
    """What one step returned, in the shape every interface uses (a tuple: made on every step)."""

    observation: str
    reward: float
    terminated: bool
    truncated: bool
    info: dict


def pick(domain: CompiledDomain, seed: int, task: str | None = None, persona: str | None = None) -> tuple:
    """(task, persona) for an episode: the given ones, else drawn from `seed` (the same seed, the same
    draw, in any process). KeyError names the unknown id and the choices."""
    if task is None or persona is None:
        rng = random.Random(seed)
        task = task if task is not None else rng.choice([t.id for t in domain.tasks])
        persona = persona if persona is not None else rng.choice([p.id for p in domain.personas])
    if task not in domain.task:
        raise KeyError(f"unknown task '{task}' (tasks: {', '.join(domain.task)})")
    if persona not in domain.persona:
        raise KeyError(f"unknown persona '{persona}' (personas: {', '.join(domain.persona)})")
    return task, persona


def make_user(domain: CompiledDomain, task: str, persona: str, user=None):
    """The user that answers questions: the offline user (`None` or "offline", as `adapt rollout` uses),
    or any object with `.answer(question, dialogue)` or a callable, used as given."""
    from ..agents.users import OfflineUser

    if user is None or user == "offline":
        return OfflineUser(domain, domain.persona[persona], domain.task[task])
    if isinstance(user, str):
        raise ValueError(f"unknown user '{user}' (only 'offline' by name; pass an object for others)")
    return user


class Session:
    """A running episode with its reward mode (`final`: the satisfaction rate p+/(p+ + p-) when the
    episode ends, 0 before; `progress`: each step, the change in the number of preferences satisfied)."""

    def __init__(self, env: Env, seed: int, reward: str = "final", prior: tuple = ()):
        if reward not in REWARDS:
            raise ValueError(f"unknown reward '{reward}' (choose from: {', '.join(REWARDS)})")
        self.env, self.seed, self.reward_mode, self.prior = env, seed, reward, tuple(prior)
        self.layout = env.reset()
        self._satisfied = 0
        self._final = None

    @classmethod
    def open(cls, domain: CompiledDomain, task: str | None = None, persona: str | None = None, seed: int = 0,
             user=None, reward: str = "final", max_steps: int = MAX_STEPS, prior=()) -> Session:
        """A fresh episode: task and persona given or drawn from `seed`; scene from `seed` (as `adapt rollout`)."""
        if not isinstance(seed, numbers.Integral) or isinstance(seed, bool) or seed < 0:
            raise ValueError(f"seed must be an integer >= 0 (got {seed!r})")
        seed = int(seed)  # numpy integers too
        task, persona = pick(domain, seed, task, persona)
        env = Env(domain, task=task, persona=persona, seed=seed, user=make_user(domain, task, persona, user),
                  max_steps=max_steps)
        return cls(env, seed, reward, _prior(domain, persona, prior))

    @property
    def task(self) -> str:
        """The task id."""
        return self.env.task.id

    @property
    def persona(self) -> str:
        """The persona id (hidden from the agent; in `info` for logging)."""
        return self.env.persona.id

    @property
    def done(self) -> bool:
        """Whether the episode is over (Declare Done or the step limit)."""
        return self.env.done

    def opening(self) -> str:
        """The first observation: the task, any preferences known in advance (`prior`) and the layout."""
        lines = [f"Task: {self.env.task.text}"]
        if self.prior:
            lines.append("Known preferences: " + " ".join(self.prior))
        lines += ["You are in a house with this layout:", self.layout]
        return "\n".join(lines)

    def info(self) -> dict:
        """What an episode's `reset` returns besides the observation."""
        return {"task": self.task, "persona": self.persona, "seed": self.seed, "scene": self.env.scene.scene_id,
                "max_steps": self.env.max_steps, "reward": self.reward_mode}

    def step(self, text) -> Outcome:
        """Take one action string exactly as a policy wrote it. A failed parse or a failed action is a step
        with ok=False and the simulator's message; text that is not a string, or longer than
        MAX_ACTION_CHARS, fails the same way. After the end: 'The episode is over.', nothing changes."""
        env = self.env
        w = env.world
        if env.done:
            return Outcome("The episode is over.", 0.0, w.done, not w.done,
                           {"step": w.step, "ok": False, "action": None, "over": True})
        if type(text) is not str or len(text) > MAX_ACTION_CHARS:
            text = _action_text(text)
        r = env.step(text)
        event = w.trace[-1]
        info = {"step": event.step, "ok": r.ok, "action": event.action, "args": dict(event.args),
                "reply": r.reply}
        terminated = w.done
        over = terminated or w.step >= env.max_steps
        reward = self._reward(info, over) if over or self.reward_mode != "final" else 0.0
        obs = with_reply(r.observation, r.reply) if r.reply else r.observation
        return Outcome(obs, reward, terminated, over and not terminated, info)

    def _reward(self, info: dict, over: bool) -> float:
        if self.reward_mode == "final" and not over:
            return 0.0
        ev = self.env.evaluate()
        if over:
            self._final = ev
            info["verdicts"] = ev.as_dict()
        if self.reward_mode == "final":
            return ev.satisfaction_rate or 0.0
        delta = ev.satisfied - self._satisfied
        self._satisfied = ev.satisfied
        return float(delta)

    def evaluation(self):
        """The verifiers' verdicts on the episode so far (`runtime.verify.Evaluation`)."""
        return self._final if self._final is not None else self.env.evaluate()

    def grammar(self, level: str = "observed") -> str:
        """The Lark grammar of the actions valid in the current state (what constrained decoding uses)."""
        from ..grammars import GrammarCache
        from ..runtime.index import runtime_index

        cache = self.env.domain.derived("envs.grammar_cache", lambda d: GrammarCache(runtime_index(d).grammar))
        return cache.state(self.task, self.env.observed(), level).text


def with_reply(observation: str, reply: str) -> str:
    """The observation an agent reads: the simulator's, then the user's reply to a question on its own line."""
    if not reply:
        return observation
    return f"{observation}\nUser: {reply}" if observation else f"User: {reply}"


def _action_text(text) -> str:
    """The text to step: the action as given; anything else becomes text the parser rejects with its message."""
    if not isinstance(text, str):
        return repr(text)[:200]
    if len(text) > MAX_ACTION_CHARS:
        return text[:200] + f"... ({len(text)} characters)"
    return text


def _prior(domain: CompiledDomain, persona: str, prior) -> tuple:
    """Preference texts the agent is told in advance: a list of texts or preference ids of the persona,
    "all" for every one (the fully informed setting), empty for none (the benchmark's default)."""
    prefs = domain.persona[persona].preferences
    if prior == "all":
        return tuple(p.text for p in prefs)
    if isinstance(prior, str):
        prior = (prior,)
    by_id = {p.id: p.text for p in prefs}
    return tuple(by_id.get(p, p) for p in prior or ())
