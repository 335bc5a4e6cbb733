"""`adapt model pretrain`: replaying records into planner prompts, TRL's SFT trainer on the actions only, and a
few updates on the tiny model that `adapt rollout` then loads."""

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


def test_trl_loss_is_the_mean_nll_of_the_action_tokens(domain, backend, tiny, tmp_path):
    import torch
    from transformers import AutoModelForCausalLM
    from trl import SFTTrainer

    from adaptbench.training.pretrain import IGNORE, completion_dataset, examples, sft_config

    (ids, labels), = examples(domain, [_oracle_record(domain)], backend.tokenizer)[0]
    model = AutoModelForCausalLM.from_pretrained(tiny, dtype=torch.float32)
    trainer = SFTTrainer(model=model, args=sft_config(tmp_path, 1, 1e-3), processing_class=backend.tokenizer,
                         train_dataset=completion_dataset([(ids, labels)]))
    batch = trainer.data_collator([trainer.train_dataset[0]])
    assert batch["input_ids"][0].tolist() == ids and batch["labels"][0].tolist() == labels  # nothing cut, prompt masked
    with torch.no_grad():
        loss = trainer.compute_loss(model, batch).item()
        logits = model(input_ids=torch.tensor([ids])).logits[0, :-1]
    where = torch.tensor(labels[1:]) != IGNORE
    expected = torch.nn.functional.cross_entropy(logits[where], torch.tensor(labels[1:])[where]).item()
    assert abs(loss - expected) < 1e-4, (loss, expected)


def test_cli_pretrain_saves_a_model_rollout_loads(domain, tiny, tmp_path, capsys):
    from adaptbench.cli import main

    data = tmp_path / "oracle.jsonl"
    data.write_text(json.dumps(_oracle_record(domain)) + "\n" + "not json\n")
    out = tmp_path / "pre"
    assert main(["model", "pretrain", "--model", str(tiny), "--data", str(data), "--out", str(out),
                 "--steps", "3", "--budget", "1500", "--quiet", "--lr", "1e-2"]) == 0
    said = capsys.readouterr()
    assert "trained on" in said.out and "for 3 updates" in said.out and "{'loss'" not in said.out + said.err
    assert not (out / "trainer").exists()
    trained = _weights(out)
    assert any((trained[k] != v).any() for k, v in _weights(tiny).items())  # the updates changed the weights
    runs = tmp_path / "r.jsonl"
    assert main(["rollout", "--agent", "planner", "--model", str(out), "--personas", "juan", "--tasks", "eggs",
                 "--seeds", "0", "--max-steps", "3", "--out", str(runs), "--quiet"]) == 0
    rec = json.loads(runs.read_text().splitlines()[0])
    assert rec["agent"] == "planner" and len(rec["steps"]) == 3 and all(s["completion"] for s in rec["steps"])
    assert main(["model", "pretrain", "--model", str(tiny), "--data", str(tmp_path / "none.jsonl"),
                 "--out", str(out)]) == 2


def _weights(path):
    from safetensors.torch import load_file

    return load_file(str(path / "model.safetensors"))


# ------------------------------------------------------------------ resumable pretraining
class Killed(Exception):
    """Stands for a kill in the middle of training."""


def _kill_at(update: int):
    def on_checkpoint(i, model, loss):
        if i == update:
            raise Killed

    return on_checkpoint


def _micro(domain, tmp_path):
    """A 32x1 model and the first 4 steps of an oracle episode (toast and coffee) to train it on."""
    from adaptbench.llm.tiny import init_tiny

    rec = _oracle_record(domain, "toast_coffee", 100)
    data = tmp_path / "oracle.jsonl"
    data.write_text(json.dumps({**rec, "steps": rec["steps"][:4]}) + "\n")
    return init_tiny(domain, tmp_path / "init", hidden=32, layers=1), data


def test_a_killed_pretraining_resumes_to_the_weights_of_an_uninterrupted_run(domain, tmp_path):
    import pytest

    from adaptbench.training.pretrain import last_checkpoint, pretrain

    init, data = _micro(domain, tmp_path)
    quiet = lambda m: None  # noqa: E731

    def train(name, **kw):
        return pretrain(domain, init, [data], tmp_path / name, steps=4, lr=1e-2, log=quiet,
                        checkpoints=tmp_path / f"{name}-ck", save_every=2, **kw)

    whole = train("whole")
    assert whole.resumed_from == 0 and last_checkpoint(tmp_path / "whole-ck")[0] == 4
    with pytest.raises(Killed):  # after update 2's checkpoint, before update 4's
        train("cut", every=2, on_checkpoint=_kill_at(4))
    assert last_checkpoint(tmp_path / "cut-ck")[0] == 2 and not (tmp_path / "cut").exists()
    said = []
    resumed = pretrain(domain, init, [data], tmp_path / "cut", steps=4, lr=1e-2, log=said.append,
                       checkpoints=tmp_path / "cut-ck", save_every=2)
    assert any("resuming from update 2 of 4" in m for m in said) and resumed.resumed_from == 2
    a, b = _weights(tmp_path / "whole"), _weights(tmp_path / "cut")
    assert all((a[k] == b[k]).all() for k in a)  # bit-identical: optimizer, scheduler, RNG and data order resumed
    assert (resumed.first_loss, resumed.last_loss) == (whole.first_loss, whole.last_loss)  # the whole loss history
    again = []
    assert pretrain(domain, init, [data], tmp_path / "cut", steps=4, lr=1e-2, log=again.append,
                    checkpoints=tmp_path / "cut-ck") == resumed and "already trained" in again[0]
    with pytest.raises(ValueError, match="another pretraining run .*steps"):
        pretrain(domain, init, [data], tmp_path / "cut", steps=6, lr=1e-2, log=quiet, checkpoints=tmp_path / "cut-ck")


def test_a_killed_curve_keeps_its_points_and_evaluates_no_checkpoint_twice(domain, tmp_path, monkeypatch):
    import pytest

    from adaptbench.training import curve

    _, data = _micro(domain, tmp_path)
    evaluated = []

    def fake_evaluate(domain_, model_dir, jobs, out, s):
        update = int(out.stem.removeprefix("eval-"))
        if update == 4 and not evaluated.count(4):
            evaluated.append(4)
            raise Killed  # a kill in the middle of update 4's evaluation
        evaluated.append(update)
        return {"episodes": 1, "dishes": update, "dishes_of": 8, "satisfaction": update / 8}

    monkeypatch.setattr(curve, "evaluate", fake_evaluate)
    s = curve.CurveSettings(seeds=(100,), sizes=((32, 1),), steps=6, every=2, lr=1e-2)
    with pytest.raises(Killed):
        curve.train_size(domain, data, (32, 1), s, tmp_path / "c", [], log=lambda m: None)
    here = tmp_path / "c" / "h32-l1"
    before = curve.read_points(here / "points.jsonl")
    assert list(before) == [2] and (here / "trainer" / "checkpoint-2" / "trainer_state.json").is_file()
    entry = curve.train_size(domain, data, (32, 1), s, tmp_path / "c", [], log=lambda m: None)
    assert evaluated == [2, 4, 4, 6]  # update 2 not again; the killed one once more
    assert [p["update"] for p in entry["points"]] == [2, 4, 6] and entry["points"][0] == before[2]
    assert all(p["loss"] is not None for p in entry["points"]) and entry["pretrain"]["resumed_from"] == 2
    done = curve.train_size(domain, data, (32, 1), s, tmp_path / "c", [], log=lambda m: None)
    assert evaluated == [2, 4, 4, 6] and done["points"] == entry["points"]  # a finished size: nothing again
