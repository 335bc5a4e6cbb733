"""ADAPT as a Gymnasium environment: text actions in, text observations out.

    import gymnasium as gym
    import adaptbench.envs                      # registers adaptbench/Breakfast-v0
    env = gym.make("adaptbench/Breakfast-v0")          # spec=DIR for your own spec
    obs, info = env.reset(seed=3, options={"persona": "juan", "task": "eggs"})
    obs, reward, terminated, truncated, info = env.step('Ask "How do you like your eggs?"')

The episode is the one `adapt rollout` runs for (persona, task, seed): the same scene, offline user and
verifiers (`envs.session.Session`). Without options, the task and persona are drawn from the seed.
"""

from __future__ import annotations

import re
import string

import gymnasium as gym
from gymnasium import spaces

from ..runtime.env import MAX_STEPS
from .session import MAX_ACTION_CHARS, Session

MAX_OBSERVATION_CHARS = 1 << 16
_ASCII_OUTSIDE = re.compile(r"[\x00-\x08\x0e-\x1f\x7f]")  # the ASCII characters string.printable lacks


def charset(domain) -> frozenset:
    """The characters observations may hold: printable ASCII and whitespace, plus every character of the
    spec's own text (names, descriptions, preferences, answers, messages)."""
    def build(d) -> frozenset:
        from ..llm.tiny import corpus

        chars = set(string.printable)
        for text in corpus(d):
            chars.update(text)
        return frozenset(chars)

    return domain.derived("envs.charset", build)


class AdaptEnv(gym.Env):
    """`adaptbench/Breakfast-v0`. Arguments: `spec` (a spec directory or a compiled domain; default the
    paper's spec shipped with adaptbench, $ADAPT_SPEC overrides), `task` and
    `persona` (fixed for every episode unless reset's options say otherwise; default: drawn from the
    seed), `reward` ("final" or "progress", see docs/environments.md), `max_steps`, `user` (None: the
    offline user), `grammar` (put the state's action grammar in every step's info)."""

    metadata = {"render_modes": ["ansi"], "render_fps": 4}

    def __init__(self, spec=None, task: str | None = None, persona: str | None = None, reward: str = "final",
                 max_steps: int = MAX_STEPS, user=None, grammar: bool = False, render_mode: str | None = None):
        from ..compiler import load_domain

        self.domain = load_domain(spec) if spec is None or isinstance(spec, str) or hasattr(spec, "__fspath__") else spec
        self.task, self.persona, self.reward_mode = task, persona, reward
        self.max_steps, self.user, self.want_grammar = max_steps, user, grammar
        self.render_mode = render_mode
        self._chars = chars = charset(self.domain)
        self.observation_space = spaces.Text(MAX_OBSERVATION_CHARS, min_length=0, charset=chars)
        self.action_space = spaces.Text(MAX_ACTION_CHARS, min_length=1, charset=chars)
        self.session: Session | None = None
        self._last = ""

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode. `seed` is the scene seed (None: drawn from the environment's generator);
        `options` may name "persona", "task", "user" and "prior" (preference ids or texts the agent is
        told, or "all"). Returns the opening observation (task and layout) and info."""
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"persona", "task", "user", "prior"}
        if unknown:
            raise ValueError(f"unknown reset option(s) {sorted(unknown)} (persona, task, user, prior)")
        scene_seed = seed if seed is not None else int(self.np_random.integers(0, 2**31 - 1))
        self.session = Session.open(self.domain, options.get("task", self.task), options.get("persona", self.persona),
                                    scene_seed, options.get("user", self.user), self.reward_mode, self.max_steps,
                                    options.get("prior", ()))
        self._last = self.session.opening()  # the spec's own text only: inside the charset by construction
        info = self.session.info()
        if self.want_grammar:
            info["grammar"] = self.session.grammar()
        return self._last, info

    def step(self, action):
        """One action string, exactly as the policy wrote it; a failed parse is a failed step
        (info["ok"] False, the simulator's message as the observation), never an exception."""
        if self.session is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        obs, reward, terminated, truncated, info = self.session.step(action)
        self._last = obs = self._clean(obs)
        if self.want_grammar and not (terminated or truncated):
            info["grammar"] = self.session.grammar()
        return obs, reward, terminated, truncated, info

    def render(self):
        """The last observation (render mode "ansi")."""
        return self._last if self.render_mode == "ansi" else None

    def _clean(self, text: str) -> str:
        """The observation inside the observation space: a character outside the spec's (only possible when
        the simulator echoes an action's odd characters) becomes '?'; the length is capped."""
        if text.isascii() and not _ASCII_OUTSIDE.search(text):
            return text[:MAX_OBSERVATION_CHARS]  # printable ASCII and whitespace: always in the charset
        if not self._chars.issuperset(text):
            text = "".join(c if c in self._chars else "?" for c in text)
        return text[:MAX_OBSERVATION_CHARS]


ENV_ID = "adaptbench/Breakfast-v0"


def register() -> None:
    """Register `adaptbench/Breakfast-v0` with Gymnasium (once)."""
    if ENV_ID not in gym.registry:
        gym.register(ENV_ID, entry_point="adaptbench.envs.gym:AdaptEnv", disable_env_checker=False)
