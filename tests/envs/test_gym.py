"""The Gymnasium env: the same episode as `adapt replay`, check_env, rewards, failures as steps."""

from __future__ import annotations

import io
import json
from contextlib import redirect_stdout

import pytest

gym = pytest.importorskip("gymnasium", reason="the envs extra is not installed: pip install -e '.[envs]'")


@pytest.fixture
def env(domain):
    import adaptbench.envs  # noqa: F401 - registers the id

    return gym.make("adaptbench/Breakfast-v0", spec=domain)


def _replay(tmp_path, ep) -> dict:
    from adaptbench.cli.main import main
    from tests.conftest import SPEC

    path = tmp_path / "actions.txt"
    path.write_text("\n".join(ep["actions"]) + "\n")
    out = io.StringIO()
    with redirect_stdout(out):
        rc = main(["replay", "--spec", str(SPEC), "--task", ep["task"], "--persona", ep["persona"],
                   "--seed", str(ep["seed"]), str(path), "--json"])
    assert rc == 0
    return json.loads(out.getvalue())


def test_episode_equals_adapt_replay(env, oracle_eggs, tmp_path):
    from adaptbench.envs.session import with_reply

    ep = dict(oracle_eggs, actions=['Ask "How do you like your eggs?"', "Crack the moon"] + oracle_eggs["actions"])
    replay = _replay(tmp_path, ep)
    obs, info = env.reset(seed=0, options={"task": "eggs", "persona": "juan"})
    assert "Prepare eggs" in obs and info["scene"] == replay["scene"]
    seen, total = [], 0.0
    for a in ep["actions"]:
        obs, reward, terminated, truncated, info = env.step(a)
        seen.append((obs, info["ok"]))
        total += reward
    assert seen == [(with_reply(s["observation"], s["reply"]), s["ok"]) for s in replay["steps"]]
    assert terminated and not truncated
    assert info["verdicts"]["preferences"] == replay["preferences"]
    assert reward == pytest.approx(replay["satisfaction_rate"]) and total == reward
    assert replay["steps"][0]["reply"] and not replay["steps"][1]["ok"]  # an answered question, a failed parse


def test_check_env_passes(env):
    from gymnasium.utils.env_checker import check_env

    check_env(env.unwrapped, skip_render_check=False)


def test_failed_parse_is_a_step_not_an_exception(env):
    env.reset(seed=0, options={"task": "eggs", "persona": "juan"})
    obs, reward, terminated, truncated, info = env.step("fry the universe")
    assert not info["ok"] and "I don't understand 'fry the universe'" in obs
    assert (reward, terminated, truncated, info["step"]) == (0.0, False, False, 1)
    obs, *_, info = env.step(12345)  # not even a string
    assert not info["ok"] and info["step"] == 2
    obs, *_, info = env.step("x" * 10_000)  # oversize: fails, quoting only its start
    assert not info["ok"] and "(10000 characters)" in obs and len(obs) < 2000


def test_progress_reward_sums_to_satisfied_and_step_limit_truncates(domain, oracle_eggs):
    from adaptbench.envs.gym import AdaptEnv

    env = AdaptEnv(domain, reward="progress")
    env.reset(seed=0, options={"task": "eggs", "persona": "juan"})
    rewards = [env.step(a)[1] for a in oracle_eggs["actions"]]
    satisfied = sum(v["verdict"] == "satisfied" for v in oracle_eggs["verdicts"]["preferences"])
    assert sum(rewards) == satisfied > 0 and rewards[-1] >= 0
    short = AdaptEnv(domain, max_steps=2)
    short.reset(seed=0, options={"task": "eggs", "persona": "juan"})
    short.step("Look for eggs")
    *_, terminated, truncated, info = short.step("Look for milk")
    assert truncated and not terminated and "verdicts" in info


def test_reset_draws_persona_and_task_from_the_seed_and_checks_options(domain):
    from adaptbench.envs.gym import AdaptEnv

    env = AdaptEnv(domain, grammar=True)
    a = env.reset(seed=7)[1]
    b = env.reset(seed=7)[1]
    assert a == b and a["persona"] in domain.persona and "start: action" in a["grammar"]
    with pytest.raises(KeyError, match="unknown persona 'zed'"):
        env.reset(seed=0, options={"persona": "zed"})
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(seed=0, options={"colour": "red"})
    obs, info = env.reset(seed=0, options={"task": "eggs", "persona": "juan", "prior": "all"})
    assert "Known preferences:" in obs
