"""`adapt model ship` (training.ship): a trained method of a reproduce run made a named model with its
provenance, which `adapt eval` then reads (method, split, seeds); refused, with one line and nothing
changed, when the method has not finished training. Stand-in model files: no torch needed."""

from __future__ import annotations

import json

import pytest

from adaptbench.harness.methods import read_provenance, trained_seeds
from adaptbench.harness.record import EpisodeRecord


def _record(agent, persona, seed, rate, model=None, split=None):
    return EpisodeRecord(agent=agent, persona=persona, task="eggs", seed=seed, satisfied=1, violated=1,
                         satisfaction_rate=rate, questions=0, completed=("eggs",), split=split,
                         agent_config={"agent": agent, "model": model} if model else {})


def _run(tmp_path, finished=True):
    """A stand-in `adapt train reproduce` OUT with a given base and a trained dpo."""
    run = tmp_path / "run"
    student = {"split": "0", "scene_seeds": [100, 101], "teacher": "oracle"}
    (run / "base").mkdir(parents=True)
    (run / "base" / "done.json").write_text(json.dumps({"stage": "base", "given": {
        "base": "/models/base", "weights_sha256": ["ab"], "student": student}}))
    (run / "pairs").mkdir()
    (run / "pairs" / "summary.json").write_text(json.dumps({"rows": 10, "split": "0"}))
    merged = run / "dpo" / "merged"
    merged.mkdir(parents=True)
    for f in ("config.json", "tokenizer.json", "tokenizer_config.json"):
        (merged / f).write_text("{}")
    (merged / "model.safetensors").write_bytes(b"weights")
    (merged / "optimizer.pt").write_bytes(b"not a model file")
    (run / "dpo" / "settings.json").write_text(json.dumps({"lr": 3e-4, "max_steps": 60}))
    if finished:
        (run / "dpo" / "train.json").write_text(json.dumps({"method": "dpo", "split": "0", "scene_seeds": [100],
                                                             "steps": 60}))
    (run / "eval").mkdir()
    base = [_record("planner", p, s, 0.5, "/models/base") for p in ("leila", "juan") for s in (0, 1)]
    dpo = [_record("planner", p, s, 0.5 + 0.25 * (p == "leila"), str(merged)) for p in ("leila", "juan")
           for s in (0, 1)]
    (run / "eval" / "base.jsonl").write_text("".join(r.to_json() + "\n" for r in base))
    (run / "eval" / "dpo.jsonl").write_text("".join(r.to_json() + "\n" for r in dpo))
    return run


def test_ship_copies_the_model_files_and_writes_the_provenance_eval_reads(domain, tmp_path):
    from adaptbench.training.ship import ship

    dest = tmp_path / "student-rdpo"
    rec = ship(_run(tmp_path), "dpo", dest, "student-rdpo", domain, log=lambda m: None)
    assert sorted(p.name for p in dest.iterdir()) == ["config.json", "model.safetensors", "tokenizer.json",
                                                      "tokenizer_config.json", "training.json"]
    prov = read_provenance(str(dest))
    assert prov["method"] == "dpo" and str(prov["split"]) == "0" and prov["name"] == "student-rdpo"
    assert trained_seeds(str(dest)) == (100, 101)  # the base's seeds count as trained on too
    assert prov["base"]["base"] == "/models/base" and prov["data"] == {"rows": 10, "split": "0"}
    assert prov["weights_sha256"] == rec["weights_sha256"] and len(rec["weights_sha256"]) == 64
    ev = prov["evaluation"]
    assert ev["rows"]["planner"]["episodes"] == 4 and ev["rows"]["reflection-dpo"]["dishes"] == 4
    unseen = [p for p in ev["paired_with_base"] if p["personas"] == "unseen"]
    assert unseen and unseen[0]["difference"][0] == pytest.approx(25.0)  # leila is split 0's unseen persona


def test_ship_refuses_an_unfinished_method_and_leaves_the_destination(domain, tmp_path):
    from adaptbench.cli import main

    dest = tmp_path / "keep"
    dest.mkdir()
    (dest / "model.safetensors").write_bytes(b"old")
    run = _run(tmp_path, finished=False)
    assert main(["model", "ship", "--run", str(run), "--method", "dpo", "--name", "x", "--dest", str(dest)]) == 1
    assert (dest / "model.safetensors").read_bytes() == b"old"
