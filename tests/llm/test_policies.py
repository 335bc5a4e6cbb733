"""LLM policies, the LLM user and `adapt rollout --model` at smoke scale on the tiny model (CPU)."""

from __future__ import annotations

import json

import pytest

from adaptbench.harness.rollout import Job
from adaptbench.llm.policies import AGENTS

from .conftest import SKIP_MODELS, play

pytestmark = SKIP_MODELS


def _offline(d, p, t):
    from adaptbench.agents.users import OfflineUser

    return OfflineUser(d, p, t)


@pytest.mark.parametrize("agent", list(AGENTS))
def test_each_agent_runs_batched_and_every_action_parses(domain, backend, agent):
    from adaptbench.harness.batches import max_steps, run_batched
    from adaptbench.llm.policies import LLMPolicy

    policy = LLMPolicy(backend, domain, agent, max_tokens=16, every=2)
    jobs = [Job(agent, "juan", "eggs", 0), Job(agent, "miranda", "cereal", 1)]
    recs = list(run_batched(jobs, domain, policy, _offline, batch=2, steps=3))
    n = max_steps(policy, 3)  # the budget, 3; always-ask (a question every 2 steps) 3 x (1 + 1/2) = 4
    assert n == (4 if AGENTS[agent] == "always_ask" else 3)
    assert sorted((r["persona"], r["n_steps"]) for r in recs) == [("juan", n), ("miranda", n)]
    for r in recs:
        assert r["agent_config"]["agent"] == agent and r["agent_config"]["prompt"] == AGENTS[agent]
        for s in r["steps"]:
            st = s["stats"]
            assert st["parsed"] is not None and st["accepted"], s
            assert st["batch"] == 2 and st["prompt_tokens"] > 500 and 0 < st["tokens"] <= 16
            if agent == "never-ask-llm":
                assert st["parsed"] != "ask"
            if agent == "always-ask-llm" and st["grammar"] == "ask_only":
                assert st["parsed"] == "ask"
        if agent == "always-ask-llm":
            acts = [s["action"] for s in r["steps"]]
            assert any(a.startswith("Ask ") for a in acts[:2]) or acts[2].startswith("Ask ")


def test_teacher_prompt_holds_preferences_and_unmet_ones(domain, backend):
    from adaptbench.llm.policies import LLMPolicy

    ep, _ = play(domain, agent="teacher")
    policy = LLMPolicy(backend, domain, "teacher")
    policy.start(ep.id, ep.env)
    prompt, _grammar, force = policy._prepare(ep.view())
    assert not force
    assert "Add whole milk while preparing eggs" in prompt.messages[0]["content"]
    assert "Preferences not yet met:\n- Prefer hearty scrambled eggs" in prompt.messages[-1]["content"]
    planner = LLMPolicy(backend, domain, "planner")
    assert "whole milk" not in planner._prepare(ep.view())[0].messages[0]["content"]


def test_always_ask_switches_to_the_ask_only_grammar(domain, backend):
    from adaptbench.llm.policies import LLMPolicy

    policy = LLMPolicy(backend, domain, "always-ask-llm", every=2)
    ep, _ = play(domain, steps=("Look for eggs", "Open fridge_0"))
    prompt, grammar, force = policy._prepare(ep.view())
    assert force and "action: ask" in grammar and prompt.prefix == "Action: "
    assert "your next action must be a question" in prompt.messages[-1]["content"]
    ep, _ = play(domain, steps=("Look for eggs", 'Ask "Eggs?"'))
    assert not policy._prepare(ep.view())[2]


def test_a_bank_policy_asks_only_the_domains_questions(domain, backend):
    from adaptbench.grammars.index import domain_questions
    from adaptbench.harness.batches import run_batched
    from adaptbench.llm.policies import LLMPolicy

    policy = LLMPolicy(backend, domain, "always-ask-llm", every=1, max_tokens=40, questions="bank")
    assert policy.config()["questions"] == "bank" and "questions" not in LLMPolicy(backend, domain).config()
    rec = next(iter(run_batched([Job("always-ask-llm", "juan", "eggs", 0)], domain, policy, _offline, batch=1,
                                steps=3)))
    asked = [s["action"] for s in rec["steps"] if s["stats"]["grammar"] == "ask_only"]
    assert asked and all(a[len('Ask "'):-1] in domain_questions(domain) for a in asked), asked
    assert rec["agent_config"]["questions"] == "bank"
    with pytest.raises(ValueError, match="unknown question set 'some'"):
        LLMPolicy(backend, domain, questions="some")


def test_llm_user_answers_in_one_line(domain, backend):
    from adaptbench.llm.user import LLMUser

    ep, _ = play(domain)
    user = LLMUser(backend, domain, domain.persona["juan"], domain.task["eggs"], max_tokens=12).bind(ep.env)
    a = user.answer("How do you like your eggs?")
    assert a and "\n" not in a
    assert user.answer("How do you like your eggs?") == a  # greedy: same state, same answer
    prompt = user.prompt("Milk?", (("Eggs?", "Scrambled."),))
    assert "- fridge_0 (fridge)" in prompt.messages[0]["content"]
    assert [m["role"] for m in prompt.messages] == ["system", "user", "assistant", "user"]


def test_cli_rollout_with_llm_user_then_eval(tiny, tmp_path, capsys):
    from adaptbench.cli import main

    out = tmp_path / "planner.jsonl"
    argv = ["rollout", "--agent", "planner", "--model", str(tiny), "--personas", "juan", "--tasks", "eggs",
            "--seeds", "0", "--max-steps", "2", "--user", "llm", "--out", str(out), "--quiet"]
    assert main(argv) == 0
    rec = json.loads(out.read_text())
    assert rec["agent_config"]["user"] == "llm" and rec["n_steps"] == 2 and "satisfaction_rate" in rec
    assert {"prompt_tokens", "tokens", "level", "parsed", "seconds"} <= set(rec["steps"][0]["stats"])
    assert main(argv) == 0 and "0 episode(s) run, 1 already" in capsys.readouterr().out  # resumed
    assert main(["eval", str(out)]) == 0


def test_cli_rollout_records_the_question_set(tiny, tmp_path):
    from adaptbench.cli import main

    out = tmp_path / "bank.jsonl"
    assert main(["rollout", "--agent", "planner", "--model", str(tiny), "--personas", "juan", "--tasks", "eggs",
                 "--seeds", "0", "--max-steps", "1", "--question-set", "bank", "--out", str(out), "--quiet"]) == 0
    assert json.loads(out.read_text())["agent_config"]["questions"] == "bank"


def test_cli_errors_are_clear(tmp_path, capsys):
    from adaptbench.cli import main

    base = ["rollout", "--agent", "planner", "--personas", "juan", "--tasks", "eggs", "--seeds", "0",
            "--out", str(tmp_path / "x.jsonl")]
    assert main(base) == 2 and "--model is required" in capsys.readouterr().err
    assert main([*base, "--model", str(tmp_path / "nope")]) == 2
    assert "not a directory" in capsys.readouterr().err
    assert main([*base[:2], "planner,oracle", *base[3:], "--model", str(tmp_path)]) == 2


def test_an_episode_that_raises_becomes_an_error_record(domain, cereal_steps_raise):
    from adaptbench.harness.batches import run_batched
    from adaptbench.harness.policy import Decision, Policy

    class LookForEggs(Policy):
        name = "look"

        def act(self, view):
            return Decision("Look for eggs")

    jobs = [Job("look", "juan", "eggs", 0), Job("look", "juan", "cereal", 0)]
    recs = {r["task"]: r for r in run_batched(jobs, domain, LookForEggs(), _offline, batch=2, steps=2)}
    assert recs["cereal"]["error"] == "RuntimeError: boom" and "traceback" in recs["cereal"]
    assert recs["eggs"]["n_steps"] == 2


def test_llm_rollout_runs_on_the_harness_loop_one_batched_call_per_round(domain, backend, tmp_path):
    from adaptbench.harness.batches import rollout_policy
    from adaptbench.harness.record import RECORD_VERSION, EpisodeRecord
    from adaptbench.llm.policies import LLMPolicy

    class Counted(LLMPolicy):
        rows: list = []

        def act_batch(self, views):
            self.rows.append(len(views))
            return super().act_batch(views)

    policy = Counted(backend, domain, "planner", max_tokens=16)
    jobs = [Job("planner", p, t, 0) for p in ("juan", "miranda") for t in ("eggs", "cereal")] + \
        [Job("planner", "juan", "eggs", 1)]
    out = tmp_path / "p.jsonl"
    res = rollout_policy(jobs, out, domain, policy, _offline, batch=2, progress=False, steps=2)
    assert res.ran == 5 and res.errors == 0
    assert max(policy.rows) == 2 and sum(policy.rows) == 5 * 2  # slots refilled: 2 rows a round until the last
    recs = [EpisodeRecord.from_json(line) for line in out.read_text().splitlines()]
    assert all(r.version == RECORD_VERSION and r.n_steps == 2 for r in recs)
    assert all(r.config == {**policy.config(), "user": "offline", "max_steps": 2} for r in recs)
    assert all(s.completion == s.action and s.stats["batch"] in (1, 2) for r in recs for s in r.steps)
    assert rollout_policy(jobs, out, domain, policy, _offline, batch=2, progress=False, steps=2).present == 5


def test_worker_processes_split_the_jobs_and_write_what_one_process_writes(domain, tiny, tmp_path):
    import json

    from adaptbench.harness.batches import rollout_policy
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.llm.policies import LLMPolicy

    jobs = [Job("planner", p, t, s) for p in ("juan", "miranda") for t in ("eggs", "cereal") for s in (0, 1)]

    def run(workers):
        out = tmp_path / f"w{workers}.jsonl"
        policy = LLMPolicy(TransformersBackend(str(tiny)), domain, "planner", max_tokens=12)
        policy.act_batch([play(domain)[0].view()] * 4)  # the parent's mask threads exist before the fork
        res = rollout_policy(jobs, out, domain, policy, _offline, batch=2, progress=False, steps=3, workers=workers)
        assert res.ran == len(jobs) and res.errors == 0
        recs = [json.loads(line) for line in out.read_text().splitlines()]
        return {(r["persona"], r["task"], r["seed"]): [s["action"] for s in r["steps"]] for r in recs}

    assert run(2) == run(1)
