"""OpenEnv's own client against the whole `adapt serve-env` process: `openenv-core`'s `GenericEnvClient`
(async, and its `.sync()` wrapper) plays whole oracle episodes over `/ws` and earns exactly the verdicts
of the same episodes run in-process; refused messages are OpenEnv error messages and leave the episode
as it was; the connection owns its session."""

from __future__ import annotations

import asyncio
import json
import time

import pytest

pytest.importorskip("starlette", reason="the envs extra is not installed: pip install -e '.[envs]'")
pytest.importorskip("websockets", reason="the envs extra is not installed: pip install -e '.[envs]'")
openenv = pytest.importorskip("openenv.core", reason="openenv-core is not installed: pip install -e '.[envs]'")

from .serverproc import request, serve_env  # noqa: E402


@pytest.fixture(scope="module")
def port():
    with serve_env("--max-sessions", "64") as p:
        yield p


def _sessions(port: int, expected: int) -> int:
    """Open sessions on the server, polled for up to 5 s until `expected` (closes land asynchronously)."""
    deadline = time.monotonic() + 5
    while (n := request(port, "GET", "/health")[1]["sessions"]) != expected and time.monotonic() < deadline:
        time.sleep(0.05)
    return n


def _sync_episode(port: int, ep: dict) -> tuple:
    with openenv.GenericEnvClient(base_url=f"http://127.0.0.1:{port}").sync() as env:
        first = env.reset(seed=ep["seed"], task=ep["task"], persona=ep["persona"])
        assert first.done is False and first.reward is None
        assert first.observation["text"].startswith("Task: ") and first.observation["info"]["task"] == ep["task"]
        result = first
        for action in ep["actions"]:
            result = env.step({"text": action})
        state = env.state()
    return result, state


async def _async_episode(port: int, ep: dict) -> tuple:
    async with openenv.GenericEnvClient(base_url=f"ws://127.0.0.1:{port}") as env:
        await env.reset(seed=ep["seed"], task=ep["task"], persona=ep["persona"])
        result = None
        for action in ep["actions"]:
            result = await env.step({"text": action})
        return result, await env.state()


def _check(result, state, ep: dict) -> None:
    assert result.done and result.observation["terminated"]
    assert result.observation["info"]["verdicts"] == ep["verdicts"] == state["verdicts"]
    assert result.reward == pytest.approx(ep["verdicts"]["satisfaction_rate"] or 0.0)
    assert state["step_count"] == len(ep["actions"]) and state["episode_id"]


def test_sync_generic_client_plays_a_whole_episode(port, oracle_eggs):
    result, state = _sync_episode(port, oracle_eggs)
    _check(result, state, oracle_eggs)
    assert _sessions(port, 0) == 0  # the session ended with its connection


def test_async_generic_clients_play_concurrently(port, oracle_mix):
    async def main():
        return await asyncio.gather(*(_async_episode(port, ep) for ep in oracle_mix))

    for (result, state), ep in zip(asyncio.run(main()), oracle_mix, strict=True):
        _check(result, state, ep)


def test_refused_messages_are_openenv_errors_and_change_nothing(port):
    async def main():
        async with openenv.GenericEnvClient(base_url=f"http://127.0.0.1:{port}") as env:
            with pytest.raises(RuntimeError, match=r"send \{\"type\": \"reset\"\} first \(code: SESSION_ERROR\)"):
                await env.step({"text": "Look for eggs"})
            await env.reset(seed=0, task="eggs", persona="juan")
            await env.step({"text": "Look for eggs"})
            for data, match in [({"text": "Look for \ud800"}, "lone surrogate"), ({"text": None}, "not null"),
                                ({"text": "x" * 3000}, "at most 2000"), ({}, "field 'action'")]:
                with pytest.raises(RuntimeError, match=match):
                    await env.step(data)
            for kwargs, match in [({"episode_id": "mine"}, "the server makes session ids"),
                                  ({"session_id": "x", "secret": "y"}, "owns its session"),
                                  ({"seed": None}, "must be an integer, not null"), ({"task": "flambe"}, "flambe")]:
                with pytest.raises(RuntimeError, match=match):
                    await env.reset(**kwargs)
            ws = env._ws  # raw frames the client would never send
            for raw, match in [("{not json", "INVALID_JSON"), ("[" * 5000, "nested too deep"),
                               (json.dumps({"type": "dance"}), "UNKNOWN_TYPE"), (b"\xff\xfe", "not valid UTF-8"),
                               (json.dumps({"type": "state", "extra": 1}), "unknown key")]:
                await ws.send(raw)
                answer = json.loads(await ws.recv())
                assert answer["type"] == "error" and 400 <= answer["data"]["status"] < 500, answer
                assert match in json.dumps(answer), (raw[:20], answer)
            return await env.state()

    state = asyncio.run(main())
    assert state["step_count"] == 1 and state["task"] == "eggs"  # only the one accepted step counted


def test_a_reset_replaces_only_this_connections_episode(port):
    async def main():
        async with openenv.GenericEnvClient(base_url=f"http://127.0.0.1:{port}") as a, \
                openenv.GenericEnvClient(base_url=f"http://127.0.0.1:{port}") as b:
            await a.reset(seed=0, task="eggs", persona="juan")
            await b.reset(seed=1, task="cereal", persona="ron")
            await b.step({"text": "Look for milk"})
            first = (await a.state())["episode_id"]
            await a.reset(seed=2, task="parfait", persona="maya")
            assert (await a.state())["episode_id"] != first
            assert _sessions(port, 2) == 2  # a's first episode is gone
            return await b.state()

    state = asyncio.run(main())
    assert (state["task"], state["step_count"]) == ("cereal", 1)
