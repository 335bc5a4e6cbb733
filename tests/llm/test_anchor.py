"""`--anchor`: a teacher's whole episodes trained beside a method's rows (training/trainers/anchor.py)."""

from __future__ import annotations

import json

import pytest

from .conftest import SKIP_MODELS
from .test_trainers import _adapt, _data


def _oracle_ask(tmp_path, seeds="100-101"):
    out = tmp_path / "oracle-ask.jsonl"
    got = _adapt("rollout", "--agent", "oracle-ask", "--personas", "sarah,ron", "--tasks", "eggs,cereal",
                 "--seeds", seeds, "--max-steps", 50, "--out", out, "--quiet")
    assert got.returncode == 0, got.stderr
    return out


@SKIP_MODELS
def test_the_stream_is_seeded_whole_episodes_with_the_loss_on_every_action(domain, tiny, tmp_path):
    from adaptbench.training.pretrain import IGNORE
    from adaptbench.training.trainers.anchor import AnchorStream
    from adaptbench.training.trainers.run import load_tokenizer

    path, tok = _oracle_ask(tmp_path), load_tokenizer(str(tiny))
    a, b = (AnchorStream.load(domain, [path], tok, seed=0) for _ in range(2))
    n = len(a.records)
    assert n == 8 and a.seeds() == {100, 101} and a.personas() == ["ron", "sarah"]
    first_pass = [a._index(i) for i in range(n)]
    assert sorted(first_pass) == list(range(n))  # each episode once a pass
    assert [b._index(i) for i in range(n)] == first_pass  # the same seed, the same order (a resumed run's)
    assert AnchorStream.load(domain, [path], tok, seed=1)._index(0) is not None
    ids, labels = a.take(0)
    record = a.records[first_pass[0]]
    trained = [t for t in labels if t != IGNORE]
    eos = trained.count(tok.eos_token_id)
    assert eos == len(record["steps"])  # every action of the episode, each with its end token
    assert len(trained) < len(ids) and all(t == i for t, i in zip(labels, ids, strict=True) if t != IGNORE)


@SKIP_MODELS
def test_dpo_and_sft_train_with_anchor_episodes_and_record_them(tiny, tmp_path):
    data, anchor = tmp_path / "data", _oracle_ask(tmp_path)
    _data(tiny, data)
    plain, anchored = tmp_path / "plain", tmp_path / "anchored"
    common = ["--data", data, "--model", tiny, "--max-steps", 1, "--batch", 1, "--logging-steps", 1, "--threads", 1]
    assert _adapt("train", "dpo", *common, "--out", plain).returncode == 0
    got = _adapt("train", "dpo", *common, "--out", anchored, "--anchor", anchor, "--anchor-per-update", 2)
    assert got.returncode == 0, got.stderr
    assert "2 anchor episode(s) a forward of 8" in got.stderr
    r, p = (json.loads((d / "train.json").read_text()) for d in (anchored, plain))
    assert r["anchor_episodes"] == 8 and r["anchor_personas"] == ["ron", "sarah"]
    assert r["anchor_episodes_not_replayed"] == 0 and r["scene_seeds"] == [100, 101]
    assert p["first"]["loss"] == pytest.approx(0.6931, abs=1e-3)  # DPO alone starts at log 2
    assert r["first"]["loss"] > p["first"]["loss"] + 0.5  # plus the untrained model's loss on the episodes
    logged = [json.loads(line) for line in (anchored / "log.jsonl").read_text().splitlines()]
    assert any(e.get("anchor_loss", 0) > 0 for e in logged)
    sft = tmp_path / "sft"
    got = _adapt("train", "sft", *common, "--out", sft, "--anchor", anchor)
    assert got.returncode == 0, got.stderr
    assert json.loads((sft / "train.json").read_text())["anchor_episodes"] == 8


@SKIP_MODELS
def test_a_bad_anchor_is_named_and_eval_seeds_are_refused(tiny, tmp_path):
    data = tmp_path / "data"
    _data(tiny, data)
    common = ["--data", data, "--model", tiny, "--max-steps", 1, "--batch", 1, "--threads", 1]
    got = _adapt("train", "dpo", *common, "--out", tmp_path / "a", "--anchor", tmp_path / "nowhere.jsonl")
    assert got.returncode == 2 and "--anchor" in got.stderr and "nowhere.jsonl" in got.stderr
    assert "Traceback" not in got.stderr
    empty = tmp_path / "empty.jsonl"
    empty.write_text('{"not": "a record"}\n')
    got = _adapt("train", "dpo", *common, "--out", tmp_path / "b", "--anchor", empty)
    assert got.returncode == 2 and "no episode records" in got.stderr
    on_eval = _oracle_ask(tmp_path, seeds="0")
    got = _adapt("train", "dpo", *common, "--out", tmp_path / "c", "--anchor", on_eval)
    assert got.returncode == 2 and "evaluation scene seeds 0" in got.stderr
    got = _adapt("train", "dpo", *common, "--out", tmp_path / "d", "--anchor", on_eval, "--anchor-per-update", 0)
    assert got.returncode == 2 and "--anchor-per-update" in got.stderr
