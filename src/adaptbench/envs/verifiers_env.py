"""ADAPT for the `verifiers` library (0.4, `verifiers.v1`): a taskset of episodes and an Env in which the
simulator plays the user side: each assistant reply is one action (text, exactly as `adapt replay`
reads it), the observation comes back as the next user turn, and the verifiers' satisfaction rate is the
episode's reward (`satisfaction_rate`, weight 1). Metrics recorded on the trace (`trace.metrics`, which
`vf-eval` averages): `preferences_satisfied`, `preferences_violated`, `questions` (questions asked),
`steps` (actions taken), `invalid_actions` (steps the simulator refused), `completed` (1 when the
assistant declared done, 0 when the step limit or the turn limit ended the episode).

The assistant is a plain chat model: its harness defaults to verifiers' tool-less `null` harness in a
local `subprocess` runtime (verifiers' own default is a bash agent in a hosted sandbox, which a text
game has no use for). The runtime runs verifiers' chat program through `uv` (the `verifiers` extra
installs it).

    from adaptbench.envs.verifiers_env import load_environment
    env = load_environment()                    # spec, personas, tasks, seeds as keyword arguments

`verifiers` finds it by the taskset id `adapt_breakfast` (a top-level alias package, since verifiers
imports a taskset id as a top-level module): `vf-eval adapt_breakfast` style runs resolve to the classes
here. The episode loop itself is `play_episode`, usable with any async `turn(text)` function.
"""

from __future__ import annotations

from ..runtime.env import MAX_STEPS
from .session import Session

SYSTEM_PROMPT = (
    "You are a household assistant making breakfast for a user whose preferences are hidden. Reply with "
    "exactly one action per turn, e.g. 'Look for eggs', 'Open fridge_0', 'Move egg_0 to counter_0', "
    "'Ask \"How do you like your eggs?\"', and 'Declare Done' when the task is complete. You are judged on "
    "how many of the user's preferences the finished breakfast satisfies.")
TASKSET_ID = "adapt_breakfast"


async def play_episode(session: Session, first_turn, next_turn) -> dict:
    """Drive one episode: `first_turn()` and `next_turn(observation)` are async and return an object with
    `terminated` and `last_reply` (a verifiers `Segment`); each reply is stepped as an action. Returns the
    outcome: reward (satisfaction rate, 0 if none applied), satisfied, violated, questions, steps."""
    segment = await first_turn()
    while not segment.terminated and not session.done:
        out = session.step(segment.last_reply.strip())
        if session.done:
            break
        segment = await next_turn(out.observation)
    ev = session.evaluation()
    trace = session.env.world.trace
    return {"reward": ev.satisfaction_rate or 0.0, "satisfied": ev.satisfied, "violated": ev.violated,
            "questions": ev.questions, "steps": session.env.world.step, "verdicts": ev.as_dict(),
            "invalid_actions": sum(1 for e in trace if not e.ok),
            "completed": int(session.env.world.done)}


def metrics(outcome: dict) -> dict:
    """The episode's metrics as verifiers records them (numbers, by name)."""
    return {"preferences_satisfied": outcome["satisfied"], "preferences_violated": outcome["violated"],
            "questions": outcome["questions"], "steps": outcome["steps"],
            "invalid_actions": outcome["invalid_actions"], "completed": outcome["completed"]}


def episodes(domain, personas=None, tasks=None, seeds=(0,)) -> list:
    """(persona, task, seed) of every episode asked for (default: all personas and tasks, seed 0)."""
    return [(p, t, int(s)) for p in (personas or domain.persona) for t in (tasks or domain.task) for s in seeds]


try:
    import verifiers.v1 as vf
except ImportError:  # the library is optional: load_environment says how to install it
    vf = None

if vf is not None:
    class AdaptTasksetConfig(vf.TasksetConfig):
        """Which episodes: the spec directory, persona and task ids (empty: all), scene seeds, step limit."""

        id: str = TASKSET_ID
        spec: str = ""  # empty: the paper's spec shipped with adaptbench
        personas: list[str] = []
        tasks: list[str] = []
        seeds: list[int] = [0]
        max_steps: int = MAX_STEPS

    class AdaptData(vf.TaskData):
        """One episode's identity (persona, task, seed) and limits, in `info`."""

        info: dict

    class AdaptTask(vf.Task[AdaptData, vf.State, vf.TaskConfig]):
        """One ADAPT episode."""

    class AdaptEnvConfig(vf.EnvConfig):
        """The one agent role: the assistant, a chat model (the tool-less `null` harness, run locally)."""

        assistant: vf.AgentConfig = vf.AgentConfig(harness={"id": "null"}, runtime={"type": "subprocess"})

    class AdaptTaskset(vf.Taskset[AdaptTask, AdaptTasksetConfig]):
        """Every (persona, task, seed) of the config, the opening observation as the prompt."""

        def load(self):
            """The tasks, in persona x task x seed order."""
            from ..compiler import load_domain

            c = self.config
            domain = load_domain(c.spec or None)
            for persona, task, seed in episodes(domain, c.personas, c.tasks, c.seeds):
                s = Session.open(domain, task, persona, seed, max_steps=c.max_steps)
                yield AdaptTask(AdaptData(name=f"{persona}/{task}/{seed}", prompt=s.opening(),
                                          system_prompt=SYSTEM_PROMPT,
                                          info={"spec": c.spec, "persona": persona, "task": task, "seed": seed,
                                                "max_steps": c.max_steps}), self.config.task)

    class AdaptVfEnv(vf.Env[AdaptEnvConfig]):
        """The simulator steps host-side as the user: reply -> action -> observation -> next turn."""

        async def run(self, task, agents):
            """Play the task's episode with the assistant; record the reward and the verdicts."""
            from ..compiler import load_domain

            info = task.data.info
            session = Session.open(load_domain(info["spec"] or None), info["task"], info["persona"], info["seed"],
                                   max_steps=info["max_steps"])
            async with agents.assistant.interaction(task) as interaction:
                outcome = await play_episode(session, interaction.turn, interaction.turn)
            trace = interaction.trace
            trace.record_reward("satisfaction_rate", outcome["reward"], 1.0)
            trace.record_metrics(metrics(outcome))
            trace.info["adapt"] = {k: outcome[k] for k in ("satisfied", "violated", "questions", "steps")}
            trace.info["verdicts"] = outcome["verdicts"]

    __all__ = ["AdaptEnvConfig", "AdaptTaskset", "AdaptTasksetConfig", "AdaptVfEnv", "load_environment",
               "play_episode"]


def load_environment(spec: str = "", personas=(), tasks=(), seeds=(0,), max_steps: int = MAX_STEPS):
    """The verifiers Env over ADAPT episodes (ImportError naming the package when verifiers is absent)."""
    if vf is None:
        raise ImportError("the verifiers library is not installed: pip install 'verifiers>=0.4'")
    config = AdaptEnvConfig(taskset=AdaptTasksetConfig(spec=str(spec), personas=list(personas), tasks=list(tasks),
                                                       seeds=[int(s) for s in seeds], max_steps=max_steps))
    return AdaptVfEnv(config)
