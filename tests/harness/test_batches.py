"""The one rollout path: several agents' policies on the batch runner, whatever the batch width or the
number of workers, write the records one episode at a time would; a policy's exception ends only its
episode."""

from __future__ import annotations

import json

from adaptbench.harness.rollout import Job, rollout
from adaptbench.runtime.users import OfflineUser

from ..conftest import SMALL


def _records(path) -> list:
    return sorted(json.dumps(json.loads(line), sort_keys=True) for line in path.read_text().splitlines())


def test_scripted_agents_write_the_same_records_at_any_width_and_worker_count(tmp_path, small_domain):
    jobs = [Job(a, p.id, "eggs", s) for a in ("oracle", "never-ask", "always-ask") for p in small_domain.personas
            for s in (0, 1)]
    runs = {}
    for batch, workers in ((1, 1), (4, 1), (3, 2)):
        out = tmp_path / f"b{batch}w{workers}.jsonl"
        res = rollout(jobs, out, workers=workers, progress=False, domain=small_domain, batch=batch)
        assert res.ran == len(jobs) and res.errors == 0
        runs[(batch, workers)] = _records(out)
    assert runs[(1, 1)] == runs[(4, 1)] == runs[(3, 2)]
    recs = [json.loads(x) for x in runs[(1, 1)]]
    assert {r["agent_config"]["agent"] for r in recs} == {"oracle", "never-ask", "always-ask"}
    assert all(r["agent_config"] == {"agent": r["agent"], "user": "offline", "max_steps": 50} for r in recs)
    assert all(r["satisfaction_rate"] == 1.0 for r in recs if r["agent"] == "oracle")


def test_a_policy_that_raises_at_start_or_while_deciding_ends_only_that_episode(tmp_path, small_domain, monkeypatch):
    from adaptbench.agents.scripted import NeverAsk, OraclePolicy

    real_start, real_act = OraclePolicy.start, NeverAsk.act

    def start(self, episode, env):
        if episode.endswith("/1"):
            raise RuntimeError("no plan")
        return real_start(self, episode, env)

    def act(self, view):
        if view.episode.endswith("/0") and view.step == 2:
            raise RuntimeError("lost")
        return real_act(self, view)

    monkeypatch.setattr(OraclePolicy, "start", start)
    monkeypatch.setattr(NeverAsk, "act", act)
    persona = small_domain.personas[0].id
    jobs = [Job(a, persona, "eggs", s) for a in ("oracle", "never-ask") for s in (0, 1)]
    out = tmp_path / "r.jsonl"
    res = rollout(jobs, out, progress=False, domain=small_domain, batch=4, make_user=OfflineUser)
    assert res.ran == 4 and res.errors == 2
    errors = {(r["agent"], r["seed"]): r["error"] for r in map(json.loads, out.read_text().splitlines()) if "error" in r}
    assert errors == {("oracle", 1): "RuntimeError: no plan", ("never-ask", 0): "RuntimeError: lost"}


def test_the_spec_of_a_rollout_can_be_named_instead_of_loaded(tmp_path):
    res = rollout([Job("never-ask", "ana", "eggs", 0)], tmp_path / "r.jsonl", spec=str(SMALL), progress=False)
    assert res.ran == 1


def test_the_progress_bar_moves_by_steps_and_ends_at_the_whole_budget(tmp_path, small_domain, capsys):
    """A model's episode can take minutes: the bar counts steps (each round's, and an episode's unused
    budget when it ends), so it moves within an episode and ends at every job's budget; with workers
    the ticks come through the pool and the records are the same."""
    from adaptbench.agents.scripted import make_policy
    from adaptbench.harness.batches import run_batched
    from adaptbench.harness.episode import Ticks

    persona = small_domain.personas[0].id
    jobs = [Job("never-ask", persona, "eggs", s) for s in (0, 1, 2)]
    items = list(run_batched(jobs, small_domain, make_policy("never-ask", small_domain), OfflineUser, batch=2,
                             steps=7, ticks=True))
    recs = [i for i in items if not isinstance(i, Ticks)]
    assert len(recs) == 3 and sum(i.steps for i in items if isinstance(i, Ticks)) == 3 * 7
    assert isinstance(items[0], Ticks) and items[0].steps == 2  # the first round: two episodes, one step each
    for workers in (1, 2):
        out = tmp_path / f"w{workers}.jsonl"
        res = rollout(jobs, out, workers=workers, progress=True, domain=small_domain, batch=2, steps=7)
        assert res.ran == 3
        lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("rollout ->")]
        assert lines and "21/21" in lines[-1] and "step" in lines[-1], lines
    assert _records(tmp_path / "w1.jsonl") == _records(tmp_path / "w2.jsonl")
