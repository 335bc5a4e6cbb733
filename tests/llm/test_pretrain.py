"""`adapt model pretrain`: replaying records into planner prompts, and a few updates on the tiny model."""

from __future__ import annotations

import json

from .conftest import SKIP_MODELS

pytestmark = SKIP_MODELS


def _oracle_record(domain, task="eggs", seed=0):
    from adaptbench.agents.scripted import play
    from adaptbench.agents.users import OfflineUser
    from adaptbench.runtime.env import Env

    env = Env(domain, task, "juan", seed, user=OfflineUser(domain, domain.persona["juan"], domain.task[task]))
    play("oracle", env)
    steps = [{"action": e.text, "ok": e.ok, "observation": e.observation, "reply": e.reply} for e in env.world.trace]
    return {"agent": "oracle", "persona": "juan", "task": task, "seed": seed, "steps": steps}


def test_examples_replay_the_record(domain, backend):
    from adaptbench.training.pretrain import IGNORE, examples, replay_views

    rec = _oracle_record(domain)
    views = replay_views(domain, rec)
    assert [a for _, _, a in views] == [s["action"] for s in rec["steps"]]
    assert views[3][0].history[-1].observation == rec["steps"][2]["observation"]
    tampered = {**rec, "steps": [{**rec["steps"][0], "observation": "something else"}, *rec["steps"][1:]]}
    data, skipped = examples(domain, [rec, tampered], backend.tokenizer, budget=1500)
    assert skipped == 1
    tok, eos = backend.tokenizer, backend.tokenizer.eos_token
    targets = [tok.decode([t for t in labels if t != IGNORE]) for _, labels in data]
    assert "".join(targets) == "".join(s["action"] + eos for s in rec["steps"])
    ids, labels = data[-1]  # a late step: its own sequence, the prompt (truncated to the budget) then the action
    assert len(ids) - sum(t != IGNORE for t in labels) <= 1500
    first = next(i for i, t in enumerate(labels) if t != IGNORE)
    assert tok.decode(ids[:first]).endswith("<|assistant|>\nAction: ") and labels[first:] == ids[first:]


def test_an_episode_is_packed_into_one_sequence(domain, backend):
    from adaptbench.llm.chat import render
    from adaptbench.llm.prompts import PromptBuilder
    from adaptbench.training.pretrain import IGNORE, examples, replay_views

    rec = _oracle_record(domain)
    (ids, labels), = examples(domain, [rec], backend.tokenizer)[0]
    tok = backend.tokenizer
    assert sum(t == tok.eos_token_id for t in labels) == len(rec["steps"])
    view, made_after, _ = replay_views(domain, rec)[4]
    prompt = tok(render(tok, PromptBuilder(domain).prompt(view, made_after=made_after)), add_special_tokens=False)
    n = len(prompt["input_ids"])
    assert ids[:n] == prompt["input_ids"]  # step 4's prompt as the policy tokenizes it, then its action
    assert tok.decode(labels[n:labels.index(tok.eos_token_id, n) + 1]) == rec["steps"][4]["action"] + "<|end|>"
    assert labels[:n].count(tok.eos_token_id) == 4 and labels == [t if t == IGNORE else ids[i] for i, t in enumerate(labels)]


def test_cli_pretrain_saves_a_loadable_model(domain, tiny, tmp_path, capsys):
    from transformers import AutoModelForCausalLM

    from adaptbench.cli import main

    data = tmp_path / "oracle.jsonl"
    data.write_text(json.dumps(_oracle_record(domain)) + "\n" + "not json\n")
    out = tmp_path / "pre"
    assert main(["model", "pretrain", "--model", str(tiny), "--data", str(data), "--out", str(out),
                 "--steps", "3", "--budget", "1500", "--quiet"]) == 0
    assert "trained on" in capsys.readouterr().out
    AutoModelForCausalLM.from_pretrained(out)
    assert main(["model", "pretrain", "--model", str(tiny), "--data", str(tmp_path / "none.jsonl"),
                 "--out", str(out)]) == 2
