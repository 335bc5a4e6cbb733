"""`bench/reply_transfer.py`: trains on answer pairs with the contrast loss and reads held-out pairs before,
during and after; `--train-top` leaves only the top layers trainable."""

from __future__ import annotations

import json

import pytest

from .bench_scripts import bench_script
from .conftest import SKIP_MODELS

pytestmark = SKIP_MODELS


@pytest.fixture(scope="module")
def rows(domain, tmp_path_factory):
    """Answer rows of two personas whose eggs differ, in one scene."""
    from adaptbench.training.answer_rows import answer_rows, write_rows

    path = tmp_path_factory.mktemp("rows") / "rows.jsonl"
    write_rows(path, answer_rows(domain, ["juan", "lisa"], [100], places=("recipe",), tasks=["eggs"]))
    return path


def test_training_reads_the_held_out_sets_at_each_evaluation(tiny, rows, tmp_path):
    s = bench_script("reply_transfer")
    out = tmp_path / "run"
    assert s.main(["--out", str(out), "--model", str(tiny), "--train", str(rows), "--held", f"same={rows}",
                   "--held-limit", "2", "--steps", "3", "--eval-every", "2", "--train-top", "1"]) == 0
    curve = [json.loads(line) for line in (out / "curve.jsonl").read_text().splitlines()]
    assert [c["step"] for c in curve] == [0, 2, 3]
    assert all(c["reading"]["same"]["pairs"] == 2 for c in curve)
    assert curve[-1]["loss"] == curve[-1]["loss"]  # a number, not NaN, once trained
    assert not (out / "model").exists()
    again = tmp_path / "again"
    assert s.main(["--out", str(again), "--model", str(tiny), "--train", str(rows), "--held", f"same={rows}",
                   "--held-limit", "2", "--steps", "1", "--by-choice", "--save"]) == 0
    last = json.loads((again / "curve.jsonl").read_text().splitlines()[-1])["reading"]["same"]
    assert last["all"]["pairs"] == 2 and any(k.startswith("eggs.") for k in last)
    assert (again / "model" / "config.json").is_file()
    with pytest.raises(SystemExit, match="exists"):
        s.main(["--out", str(out), "--model", str(tiny), "--train", str(rows), "--held", f"same={rows}"])


def test_freeze_below_and_bad_held_sets(tiny, rows, tmp_path):
    import torch
    from transformers import AutoModelForCausalLM

    s = bench_script("reply_transfer")
    model = AutoModelForCausalLM.from_pretrained(tiny, dtype=torch.float32)
    every = sum(p.numel() for p in model.parameters())
    assert s.freeze_below(model, 0) == every
    top = s.freeze_below(model, 1)
    expected = sum(p.numel() for p in [*model.model.layers[-1].parameters(), *model.model.norm.parameters()])
    assert top == expected < every
    assert not model.model.embed_tokens.weight.requires_grad
    with pytest.raises(SystemExit, match="NAME=PATH"):
        s.held_sets([str(rows)], 0)
    with pytest.raises(SystemExit, match="no such rows file"):
        s.held_sets([f"x={tmp_path / 'none.jsonl'}"], 0)
    held = s.held_sets([f"x={rows}"], 1)
    assert len(held["x"]) == 1
