"""The harness's episode loop: one runner for any policy, batched or not, recording every step; the
scripted agents as policies; typed, versioned run records."""

from __future__ import annotations

import json
import shutil

import pytest

from adaptbench.agents.scripted import AlwaysAsk, NeverAsk, OraclePolicy, make_policy
from adaptbench.agents.users import OfflineUser
from adaptbench.harness.episode import run_batch, run_episode
from adaptbench.harness.policy import Decision, Policy
from adaptbench.harness.record import RECORD_VERSION, EpisodeRecord, RecordError
from adaptbench.harness.records import load_runs
from adaptbench.harness.rollout import Job, rollout
from adaptbench.runtime.env import Env

from ..conftest import SPEC


def _env(domain, persona, task, seed):
    p = domain.persona[persona]
    return Env(domain, task, persona=persona, seed=seed, user=OfflineUser(domain, p, domain.task[task]))


def _texts(ep):
    return [(s.action, s.ok, s.observation, s.reply) for s in ep.steps]


class Counting(Policy):
    """Wraps a policy: counts the rows of each act_batch call and hides the env from `start`."""

    def __init__(self, inner):
        self.inner, self.rows = inner, []

    def start(self, episode, env):
        self.inner.start(episode, None)  # a non-privileged policy must not need the env

    def end(self, episode):
        self.inner.end(episode)

    def act(self, view):
        return self.inner.act(view)

    def act_batch(self, views):
        self.rows.append(len(views))
        return self.inner.act_batch(views)


@pytest.mark.parametrize("cls", [NeverAsk, AlwaysAsk])
def test_a_batch_runs_each_episode_exactly_as_alone_without_the_env(domain, cls):
    persona = domain.personas[0].id
    cases = [(t, s) for t in ("eggs", "cereal", "toast_coffee") for s in (0, 1)]
    alone = [_texts(run_episode(cls(domain), _env(domain, persona, t, s), f"{t}/{s}")) for t, s in cases]
    policy = Counting(cls(domain))
    eps = run_batch(policy, [(f"{t}/{s}", _env(domain, persona, t, s)) for t, s in cases])
    assert [_texts(e) for e in eps] == alone
    assert policy.rows[0] == len(cases) and policy.rows == sorted(policy.rows, reverse=True)
    assert policy.rows[-1] < len(cases)  # finished episodes leave the batch
    assert all(e.done and (e.steps[-1].action == "Declare Done" or len(e.steps) == 50) for e in eps)


def test_always_ask_asks_through_its_actions_and_reads_replies_from_the_history(domain):
    persona = domain.personas[0].id
    ep = run_episode(AlwaysAsk(domain), _env(domain, persona, "eggs", 0))
    asks = [s for s in ep.steps if s.action.startswith("Ask ")]
    assert asks and all(s.reply for s in asks)
    assert [t.reply for t in ep.history if t.action.startswith("Ask ")] == [s.reply for s in asks]


def test_the_oracle_plans_at_start_and_equals_its_private_simulation(domain):
    from adaptbench.agents.plans import execute
    from adaptbench.agents.scripted import Oracle

    persona = domain.personas[1].id
    env = _env(domain, persona, "toast_coffee", 2)
    policy = OraclePolicy(domain)
    ep = run_episode(policy, env)
    sim = Env(domain, "toast_coffee", persona=persona, seed=2)
    sim.reset()
    execute(sim, Oracle(domain, sim.task, sim.persona, 2, False).search())
    assert [s.action for s in ep.steps] == [e.text for e in sim.world.trace]
    assert policy._plans == {} and policy._runs == {}  # `end` forgot the episode


class Scripted(Policy):
    """A model-like policy: fixed actions, with a prompt, completion and token statistics."""

    name = "scripted-model"

    def act(self, view):
        text = "Look for mug" if view.step == 0 else "Declare Done"
        return Decision(text, prompt=[{"role": "user", "content": f"step {view.step}"}], completion=f"Action: {text}",
                        stats={"tokens": 3 + view.step})


def test_model_decisions_are_recorded_with_the_step_and_views_carry_what_the_agent_sees(domain):
    env = Env(domain, "eggs", persona=domain.personas[0].id, seed=0)
    seen_views = []

    class Spy(Scripted):
        def act(self, view):
            seen_views.append(view)
            return super().act(view)

    ep = run_episode(Spy(), env, "spy")
    assert [s.action for s in ep.steps] == ["Look for mug", "Declare Done"]
    first = ep.steps[0].to_dict()
    assert first["prompt"] == [{"role": "user", "content": "step 0"}] and first["completion"] == "Action: Look for mug"
    assert first["stats"] == {"tokens": 3}
    v0, v1 = seen_views
    assert v0.task == "eggs" and v0.task_text == domain.task["eggs"].text and "kitchen" in v0.layout.lower()
    assert v0.history == () and v1.history[0].action == "Look for mug" and v1.step == 1
    assert set(v0.observed.entities) < set(v1.observed.entities)  # the mug was found
    assert "prompt" not in run_episode(NeverAsk(domain), Env(domain, "eggs", seed=0)).steps[0].to_dict()


def test_made_lists_results_for_the_progress_line(domain):
    from adaptbench.harness.episode import made

    env = Env(domain, "eggs", seed=0)
    run_episode(NeverAsk(domain), env)
    assert made(env) and all(" in " in m for m in made(env))


def test_act_batch_must_answer_every_row(domain):
    class Short(Policy):
        def act(self, view):
            return Decision("Declare Done")

        def act_batch(self, views):
            return []

    with pytest.raises(ValueError, match="0 decisions for 2 views"):
        run_batch(Short(), [("a", Env(domain, "eggs", seed=0)), ("b", Env(domain, "eggs", seed=1))])


def test_an_exception_ends_the_batch_and_the_policy_forgets_its_episodes(domain):
    class Failing(OraclePolicy):
        def act(self, view):
            raise RuntimeError("boom")

    policy = Failing(domain)
    with pytest.raises(RuntimeError, match="boom"):
        run_batch(policy, [("a", Env(domain, "cereal", persona=domain.personas[0].id, seed=0))])
    assert policy._plans == {} and policy._runs == {}


def test_records_round_trip_and_older_versions_read(tmp_path, domain):
    persona = domain.personas[0].id
    out = tmp_path / "r.jsonl"
    rollout([Job("never-ask", persona, "cereal", 0)], out, spec=str(SPEC), progress=False)
    line = out.read_text().splitlines()[0]
    rec = EpisodeRecord.from_json(line)
    assert rec.version == RECORD_VERSION and rec.n_steps == len(rec.steps) > 3
    assert json.loads(rec.to_json()) == json.loads(line)
    legacy = {k: v for k, v in json.loads(line).items() if k not in ("version", "agent_config")}
    newer = {**json.loads(line), "version": RECORD_VERSION + 1, "seed": 1}
    with open(out, "a") as f:
        f.write(json.dumps({**legacy, "seed": 2}) + "\n" + json.dumps(newer) + "\n")
    runs = load_runs([out])
    assert [r.version for r in runs.records] == [RECORD_VERSION, 0] and runs.unversioned == 1
    assert runs.records[1].config == {"agent": "never-ask", "user": "offline"}
    assert "newer than this adaptbench reads" in runs.skipped_text()
    with pytest.raises(RecordError, match="not an episode record"):
        EpisodeRecord.from_dict({"agent": "x"})


def test_each_rollout_runs_the_spec_it_is_given(tmp_path, domain):
    other = tmp_path / "spec"
    shutil.copytree(SPEC, other)
    tasks = next(other.glob("tasks/*.yaml"))
    tasks.write_text(tasks.read_text() + "\n# a changed spec\n")
    persona = domain.personas[0].id
    job = Job("never-ask", persona, "cereal", 0)
    rollout([job], tmp_path / "a.jsonl", spec=str(SPEC), progress=False)
    rollout([job], tmp_path / "b.jsonl", spec=str(other), progress=False)
    ha = json.loads((tmp_path / "a.jsonl").read_text())["spec_hash"]
    hb = json.loads((tmp_path / "b.jsonl").read_text())["spec_hash"]
    assert ha == domain.spec_hash and hb != ha


def test_make_policy_names_every_scripted_agent(domain):
    from adaptbench.agents.scripted import AGENTS

    assert [make_policy(a, domain).name for a in AGENTS] == list(AGENTS)


def test_iter_batch_refills_slots_from_a_generator_and_matches_episodes_run_alone(domain):
    from adaptbench.harness.episode import iter_batch

    persona = domain.personas[0].id
    cases = [(t, s) for t in ("eggs", "cereal") for s in (0, 1, 2)]
    drawn = []

    def envs():
        for t, s in cases:
            drawn.append((t, s))
            yield f"{t}/{s}", _env(domain, persona, t, s)

    policy = Counting(AlwaysAsk(domain))
    stream = iter_batch(policy, envs(), width=2)
    first = next(stream)
    assert len(drawn) == 2  # episodes are drawn only as slots free up
    eps = [first, *stream]
    assert sorted(e.id for e in eps) == sorted(f"{t}/{s}" for t, s in cases)
    assert max(policy.rows) == 2 and policy.rows[-1] == 1
    for ep in eps:
        t, s = ep.id.split("/")
        assert _texts(ep) == _texts(run_episode(AlwaysAsk(domain), _env(domain, persona, t, int(s))))


def test_iter_batch_catch_turns_a_step_exception_into_that_episodes_error(domain, cereal_steps_raise):
    from adaptbench.harness.episode import iter_batch

    persona = domain.personas[0].id
    envs = [(t, _env(domain, persona, t, 0)) for t in ("eggs", "cereal")]
    eps = {ep.id: ep for ep in iter_batch(NeverAsk(domain), envs, width=2, catch=True)}
    assert eps["cereal"].error[0] == "RuntimeError: boom" and "Traceback" in eps["cereal"].error[1]
    assert eps["eggs"].error is None and eps["eggs"].done
    with pytest.raises(ValueError, match="distinct"):
        list(iter_batch(NeverAsk(domain), [("a", Env(domain, "eggs", seed=0)), ("a", Env(domain, "eggs", seed=1))]))
    with pytest.raises(ValueError, match="at least 1"):
        list(iter_batch(NeverAsk(domain), [], width=0))
