"""Sampling (`llm.sampling`, docs/llm.md *Sampling and reproducibility*): one request sampled twice gives two
samples on both generation paths and the same two again in a new process; an episode's samples do not
depend on its batch, its worker or the run's other episodes; the sample seed and temperature identify a
run (resume, `adapt eval`); prompts over `--budget` are recorded."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from ..conftest import ROOT, SPEC
from .conftest import SKIP_MODELS, play

pytestmark = [SKIP_MODELS, pytest.mark.paper]

KEY = "planner/juan/eggs/0/0/action"

def samples(model: str, spec: str, seed: int) -> dict:
    """Samples of one request, twice per path (the backend's loop, model.generate) and grammar (none, the
    state's), and of a keyed request alone, in a batch of 4, and of an unrelated key."""
    from adaptbench.compiler import load_domain
    from adaptbench.grammars import GrammarCache
    from adaptbench.harness.episode import Episode
    from adaptbench.llm.backend import Request
    from adaptbench.llm.chat import render
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.llm.prompts import PromptBuilder
    from adaptbench.runtime.env import Env
    from adaptbench.runtime.index import runtime_index

    d = load_domain(spec)
    b = TransformersBackend(str(model), temperature=1.0, seed=int(seed))
    ep = Episode("planner/juan/eggs/0", Env(d, "eggs", "juan", 0))
    text = render(b.tokenizer, PromptBuilder(d, "planner").prompt(ep.view()))
    grammar = GrammarCache(runtime_index(d).grammar).state("eggs", ep.env.observed()).text
    out = {}
    for loop in (True, False):
        b.loop = loop
        for g in (None, grammar):
            name = ("loop" if loop else "generate") + ("/grammar" if g else "")
            out[name] = [b.generate([Request(text, g, (), 12)])[0].text for _ in range(2)]
            keyed = Request(text, g, (), 12, key=KEY)
            batch = [Request(text, g, (), 12, key=f"other/{i}") for i in range(3)]
            out[name + "/key"] = [b.generate([keyed])[0].text, b.generate([batch[0], keyed, *batch[1:]])[1].text,
                                  b.generate(batch[:1])[0].text]
    return out


SCRIPT = "import json, sys; from tests.llm.test_sampling import samples; print(json.dumps(samples(*sys.argv[1:])))"


def _in_a_new_process(tiny, seed: int = 0) -> dict:
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(tiny), str(SPEC), str(seed)], capture_output=True,
                          text=True, cwd=ROOT, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def test_one_request_sampled_twice_differs_on_both_paths_repeats_in_a_new_process_and_keyed_ignores_its_batch(tiny):
    first, other = samples(tiny, SPEC, 0), samples(tiny, SPEC, 1)
    assert _in_a_new_process(tiny) == first  # a new process, the same sample seed: the same samples
    for path in ("loop", "loop/grammar", "generate", "generate/grammar"):
        a, b = first[path]
        assert a != b, path  # the run's generator is seeded once, not at every call
        alone, in_batch, unrelated = first[path + "/key"]
        assert alone == in_batch != unrelated, path  # a keyed request: its own generator, whatever the batch
        assert other[path + "/key"][0] != alone, path  # ... derived from the sample seed


def test_request_seeds_are_stable_and_the_user_answers_greedily(domain, tiny):
    from adaptbench.llm.backend import Request, request_seed
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.llm.user import LLMUser, user_config

    assert request_seed(0, KEY) == 119548773  # blake2b: the same in every process and on every machine
    assert request_seed(0, KEY) != request_seed(1, KEY) and 0 <= request_seed(7, "x") < 2**31
    b = TransformersBackend(str(tiny), temperature=1.0, seed=3)
    assert b.config()["sample_seed"] == 3 and b.config()["temperature"] == 1.0
    assert "sample_seed" not in TransformersBackend(str(tiny)).config()  # greedy: the same under every seed
    ep, _ = play(domain)
    user = LLMUser(b, domain, domain.persona["juan"], domain.task["eggs"]).bind(ep.env)
    assert user._request("x").temperature == 0.0 and user_config(b)["user_temperature"] == 0.0
    assert "user_sample_seed" not in user_config(b)
    assert user.answer("How do you like your eggs?") == user.answer("How do you like your eggs?")
    r = Request("x", key="k", temperature=0.0)
    assert b.sampler([r]).greedy and not b.sampler([Request("x")]).greedy


def test_resume_skips_an_episode_only_under_the_same_sample_seed(domain, tiny, tmp_path):
    from adaptbench.harness.batches import rollout_policy
    from adaptbench.harness.rollout import Job
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.llm.policies import LLMPolicy
    from adaptbench.runtime.users import OfflineUser

    out, jobs = tmp_path / "r.jsonl", [Job("planner", "juan", "eggs", 0)]

    def run(seed: int, temperature: float = 1.0):
        policy = LLMPolicy(TransformersBackend(str(tiny), temperature=temperature, seed=seed), domain, "planner",
                           max_tokens=8)
        res = rollout_policy(jobs, out, domain, policy, OfflineUser, progress=False, steps=1)
        return res.ran, res.present

    assert run(0) == (1, 0) and run(0) == (0, 1)  # finished under seed 0: skipped
    assert run(1) == (1, 0) and run(1) == (0, 1)  # another seed: added, then skipped
    assert run(0, 0.5) == (1, 0)  # another temperature: added
    recs = [json.loads(line) for line in out.read_text().splitlines()]
    assert [(r["agent_config"]["temperature"], r["agent_config"]["sample_seed"]) for r in recs] == \
        [(1.0, 0), (1.0, 1), (0.5, 0)]


def _rollout(tiny, out, *args):
    cmd = [sys.executable, "-m", "adaptbench.cli", "rollout", "--agent", "planner", "--model", str(tiny),
           "--spec", str(SPEC), "--personas", "juan", "--tasks", "eggs", "--max-steps", "3", "--budget", "600",
           "--temperature", "1", "--out", str(out), "--quiet", *args]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def _actions(out) -> dict:
    recs = [json.loads(line) for line in out.read_text().splitlines()]
    return {(r["seed"], r["agent_config"]["sample_seed"]): [s["action"] for s in r["steps"]] for r in recs}


def test_an_episode_samples_the_same_alone_in_a_batch_and_in_workers_and_another_seed_adds_its_episodes(tiny,
                                                                                                        tmp_path):
    alone, batch, workers = tmp_path / "alone.jsonl", tmp_path / "batch.jsonl", tmp_path / "workers.jsonl"
    _rollout(tiny, alone, "--seeds", "0", "--batch", "1")
    _rollout(tiny, batch, "--seeds", "0-3", "--batch", "4", "--sample-seed", "0")
    _rollout(tiny, workers, "--seeds", "3,2,1,0", "--batch", "2", "--workers", "2")
    episode = _actions(alone)[(0, 0)]
    assert len(episode) == 3
    assert _actions(batch)[(0, 0)] == episode == _actions(workers)[(0, 0)]
    assert _actions(batch) == _actions(workers)  # every episode, whatever its batch, worker and order
    assert "1 episode(s) run, 0 already" in _rollout(tiny, alone, "--seeds", "0", "--sample-seed", "1")
    got = _actions(alone)
    assert set(got) == {(0, 0), (0, 1)} and got[(0, 1)] != episode  # another sample seed: added, sampled anew
    recs = [json.loads(line) for line in alone.read_text().splitlines()]
    over = [s["stats"] for r in recs for s in r["steps"]]
    assert all(s["over_budget"] is True and s["over_budget_tokens"] > 0 for s in over)  # tiny prompts exceed 600
    ev = subprocess.run([sys.executable, "-m", "adaptbench.cli", "eval", str(alone)], capture_output=True, text=True,
                        cwd=ROOT, timeout=120)
    assert ev.returncode == 0, ev.stderr
    assert "planner: 2 episodes sampled at temperature 1 under 2 sample seeds (0, 1)" in ev.stdout
    assert "prompts over the token budget (with every older step left out): 6 step(s) in 2 of 2" in ev.stdout


def test_rows_are_drawn_from_their_softmax_each_with_its_own_generator():
    import collections

    import torch

    from adaptbench.llm.sampling import RowSampler, generator

    logits = torch.tensor([[0.0, 1.0, float("-inf"), 2.0], [0.0, 1.0, float("-inf"), 2.0], [float("-inf")] * 4])
    sampler = RowSampler([1.0, 0.0, 1.0], [generator(0), None, generator(1)])
    counts = collections.Counter()
    for _ in range(4000):
        row = sampler.pick(logits).tolist()
        assert row[1:] == [3, 0]  # greedy row: argmax; no token allowed: the fallback, never a masked one
        counts[row[0]] += 1
    assert counts[2] == 0
    for token, p in zip((0, 1, 3), torch.softmax(logits[0], -1)[[0, 1, 3]].tolist(), strict=True):
        assert abs(counts[token] / 4000 - p) < 0.03
    x = torch.randn(8, 512)
    batch = RowSampler([1.0] * 8, [generator(i) for i in range(8)]).pick(x)
    assert [RowSampler([1.0], [generator(i)]).pick(x[i:i + 1])[0] for i in range(8)] == batch.tolist()
