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
    from adaptbench.llm.pretrain import examples, replay_views

    rec = _oracle_record(domain)
    views = replay_views(domain, rec)
    assert [a for _, _, a in views] == [s["action"] for s in rec["steps"]]
    assert views[3][0].history[-1].observation == rec["steps"][2]["observation"]
    tampered = {**rec, "steps": [{**rec["steps"][0], "observation": "something else"}, *rec["steps"][1:]]}
    data, skipped = examples(domain, [rec, tampered], backend.tokenizer, budget=1500)
    assert skipped == 1 and len(data) == len(rec["steps"])
    p, t = data[0]
    assert backend.tokenizer.decode(t) == rec["steps"][0]["action"] + "<|end|>"
    assert backend.tokenizer.decode(p).endswith("<|assistant|>\nAction: ")


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
