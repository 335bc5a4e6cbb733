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
