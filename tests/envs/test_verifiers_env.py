"""The `verifiers` entry point: loads, lists the episodes as tasks, and scores one episode the way
`verifiers` runs it (the assistant's replies stepped as actions, the reward recorded on the trace)."""

from __future__ import annotations

import asyncio
import contextlib
from dataclasses import dataclass, field

import pytest

vf = pytest.importorskip("verifiers.v1", reason="the verifiers library is not installed (pip install 'verifiers>=0.4'); "
                         "its entry point adaptbench.envs.verifiers_env.load_environment is untested here")


@dataclass
class Segment:
    """What verifiers' `interaction.turn` returns: the assistant's reply, or the end of the exchange."""

    last_reply: str = ""
    terminated: bool = False


@dataclass
class Trace:
    rewards: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    def record_reward(self, name, value, weight=1.0):
        self.rewards[name] = (value, weight)

    def record_metrics(self, values):
        self.metrics.update({k: float(v) for k, v in values.items()})


class ScriptedAssistant:
    """An agent role whose replies are a fixed list of actions; it records the user turns it was sent."""

    def __init__(self, actions):
        self.actions, self.sent = list(actions), []

    @contextlib.asynccontextmanager
    async def interaction(self, task):
        agent = self

        class Interaction:
            trace = Trace()

            async def turn(self, message=None):
                if message is not None:
                    agent.sent.append(message)
                if not agent.actions:
                    return Segment(terminated=True)
                return Segment(agent.actions.pop(0))

        inter = Interaction()
        self.trace = inter.trace
        yield inter


def test_load_environment_and_score_one_episode(oracle_eggs):
    from adaptbench.envs.verifiers_env import AdaptTaskset, AdaptVfEnv, load_environment
    from tests.conftest import SPEC

    env = load_environment(spec=str(SPEC), personas=["juan"], tasks=["eggs", "omelette"], seeds=[0])
    assert isinstance(env, AdaptVfEnv) and isinstance(env.taskset, AdaptTaskset)
    tasks = list(env.taskset)
    assert [t.data.name for t in tasks] == ["juan/eggs/0", "juan/omelette/0"]
    assert tasks[0].data.prompt.startswith("Task: Prepare eggs")

    assistant = ScriptedAssistant(oracle_eggs["actions"])
    agents = type("Agents", (), {"assistant": assistant})()
    asyncio.run(env.run(tasks[0], agents))
    value, weight = assistant.trace.rewards["satisfaction_rate"]
    assert value == pytest.approx(oracle_eggs["verdicts"]["satisfaction_rate"]) and weight == 1.0
    assert assistant.trace.info["verdicts"]["preferences"] == oracle_eggs["verdicts"]["preferences"]
    v = oracle_eggs["verdicts"]
    assert assistant.trace.metrics == {
        "preferences_satisfied": sum(p["verdict"] == "satisfied" for p in v["preferences"]),
        "preferences_violated": sum(p["verdict"] == "violated" for p in v["preferences"]),
        "questions": v["questions"], "steps": len(oracle_eggs["actions"]), "invalid_actions": 0, "completed": 1}
    assert len(assistant.sent) == len(oracle_eggs["actions"]) - 1  # an observation after each step but the last


def test_taskset_id_resolves_through_verifiers():
    from verifiers.v1.utils.loaders import environment_class, taskset_class

    from adaptbench.envs.verifiers_env import TASKSET_ID, AdaptTaskset, AdaptVfEnv

    assert taskset_class(TASKSET_ID) is AdaptTaskset and environment_class(TASKSET_ID) is AdaptVfEnv


def test_default_assistant_is_a_local_chat_model():
    """No flag needed for a text game: the null harness (plain chat) in a local subprocess runtime."""
    from adaptbench.envs.verifiers_env import load_environment

    assistant = load_environment(personas=["juan"], tasks=["eggs"]).config.assistant
    assert assistant.harness.id == "null" and assistant.runtime.type == "subprocess"


def test_sse_relay_ends_streams_with_done():
    from adaptbench.envs.sse_relay import DONE, ensure_done

    async def collect(chunks):
        async def gen():
            for c in chunks:
                yield c
        return b"".join([c async for c in ensure_done(gen())])

    event = b'data: {"choices": []}\n\n'
    assert asyncio.run(collect([event])) == event + DONE
    assert asyncio.run(collect([event[:-1]])) == event + DONE  # an event left open is closed first
    assert asyncio.run(collect([event, DONE])) == event + DONE  # never twice
    assert asyncio.run(collect([event, b"data: [DONE]", b"\n\n"])) == event + DONE
