"""ADAPT for TRL's GRPO: an environment class for `GRPOTrainer(environment_factory=...)`.

    from trl import GRPOConfig, GRPOTrainer
    from adaptbench.envs.trl_env import environment_class, episode_dataset
    Env = environment_class(domain)                       # one class per domain (the spec a user wrote)
    data = episode_dataset(domain, personas=["juan"], seeds=range(4))
    trainer = GRPOTrainer(model, args=GRPOConfig(...), train_dataset=data, environment_factory=Env)

TRL makes one instance per rollout, calls `reset(**row)` with the dataset row (task, persona, seed; the
opening observation is appended to the prompt), exposes the public methods `act`, `ask` and `done` as
tools, and reads `get_reward()` when the rollout ends: the verifiers' satisfaction rate p+/(p+ + p-)
(0 when no preference applied). `adapt train grpo` (`envs.grpo`) drives it from the command line.
"""

from __future__ import annotations

from ..compiler.model import CompiledDomain
from .session import Session

INSTRUCTIONS = (
    "You are a household assistant making breakfast for a user whose preferences are hidden. Use the tools: "
    "`act` takes one household action (e.g. 'Look for eggs', 'Open fridge_0', 'Move egg_0 to counter_0'), "
    "`ask` asks the user one question, `done` ends the episode when the task is complete. You are judged "
    "on how many of the user's preferences the finished breakfast satisfies.")
OVER = "The episode is over."


class AdaptEnvironment:
    """One rollout's episode. Subclasses made by `environment_class` carry the domain (TRL calls the
    class with no arguments)."""

    domain: CompiledDomain | None = None
    max_steps: int = 30

    def __init__(self):
        if self.domain is None:
            raise TypeError("use adaptbench.envs.trl.environment_class(domain) to make the environment class")
        self.session: Session | None = None
        self.calls = 0

    def reset(self, task: str | None = None, persona: str | None = None, seed: int = 0, **row) -> str:
        """Start the episode named by the dataset row; returns the opening observation (task and layout)."""
        self.session = Session.open(self.domain, task, persona, int(seed), max_steps=self.max_steps)
        self.calls = 0
        return "\n\n" + self.session.opening()

    def act(self, action: str) -> str:
        """Take one household action in the kitchen.

        Args:
            action: The action exactly as the simulator reads it, e.g. 'Look for eggs', 'Open fridge_0',
                'Move egg_0 to counter_0', 'Cook items in pan_0 to get scrambled eggs'.

        Returns:
            What happened: the observation, or why the action failed.
        """
        return self._step(action)

    def ask(self, question: str) -> str:
        """Ask the user one question about their preferences.

        Args:
            question: The question, e.g. 'How do you like your eggs?'.

        Returns:
            The user's answer.
        """
        return self._step(f'Ask "{question}"')

    def done(self) -> str:
        """Declare the task done and end the episode.

        Returns:
            The closing observation.
        """
        return self._step("Declare Done")

    def get_reward(self) -> float:
        """The verifiers' satisfaction rate p+/(p+ + p-) of the episode as it stands (0 if none applied)."""
        if self.session is None:
            return 0.0
        return self.session.evaluation().satisfaction_rate or 0.0

    def _step(self, text) -> str:
        if self.session is None:
            return "Call reset first."
        if self.session.done:
            return OVER
        self.calls += 1
        out = self.session.step(text)
        return out.observation + (f"\n{OVER}" if out.terminated or out.truncated else "")


def environment_class(domain: CompiledDomain, max_steps: int = 30) -> type:
    """The environment class for `environment_factory` on `domain` (any spec, not only the paper's)."""
    return type("AdaptEnvironment", (AdaptEnvironment,), {"domain": domain, "max_steps": max_steps})


def episode_dataset(domain: CompiledDomain, personas=None, tasks=None, seeds=(0,)):
    """A `datasets.Dataset` of episodes (prompt, task, persona, seed): every persona x task x seed given
    (default: all personas and tasks of the domain). The prompt is the instructions; `reset` adds the
    episode's opening observation."""
    from datasets import Dataset

    personas = list(personas or domain.persona)
    tasks = list(tasks or domain.task)
    rows = [{"prompt": [{"role": "user", "content": INSTRUCTIONS}], "task": t, "persona": p, "seed": int(s)}
            for p in personas for t in tasks for s in seeds]
    return Dataset.from_list(rows)


TOOL_CALL_START = '<tool_call>\n{"name": "act", "arguments": {"action": "'


def tool_format_reward(completions, environments=None, **kwargs) -> list:
    """A shaping reward for models that do not call tools yet: 0.5 + 0.5 x (share of steps that succeeded)
    when the rollout took steps, else up to 0.5 for how closely the completion's start matches a tool
    call's opening. Off by default in `adapt train grpo` except for models that make no tool calls."""
    import difflib

    out = []
    for i, completion in enumerate(completions):
        env = environments[i] if environments else None
        steps = env.session.env.world.trace if env is not None and env.session is not None else []
        if steps:
            out.append(0.5 + 0.5 * sum(e.ok for e in steps) / len(steps))
            continue
        text = completion[-1]["content"] if isinstance(completion, list) else str(completion)
        text = text if isinstance(text, str) else str(text)
        out.append(0.5 * difflib.SequenceMatcher(None, text[:len(TOOL_CALL_START)], TOOL_CALL_START).ratio())
    return out
