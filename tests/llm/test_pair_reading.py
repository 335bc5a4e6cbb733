"""`bench/pair_reading.py`: a pair's reading is its two sides' margins summed, so a model that ignores the
prompts' difference reads 0 however much it prefers one action; distinctions group task and answer rows."""

from __future__ import annotations

import json

import pytest

from .bench_scripts import bench_script
from .conftest import SKIP_MODELS

pytestmark = SKIP_MODELS


def _rows(tmp_path, domain):
    """Task-contrast rows of one persona and scene, written as bench/task_rows.py writes them."""
    out = tmp_path / "rows.jsonl"
    assert bench_script("task_rows").main(["--out", str(out), "--personas", "juan", "--seeds", "100",
                                           "--only", "tea_eggs"]) == 0
    return out


def test_identical_prompts_read_nothing_and_the_margins_are_each_sides(tiny, domain, tmp_path):
    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    from adaptbench.training.answer_rows import read_rows

    s = bench_script("pair_reading")
    pairs = s.row_pairs(read_rows([_rows(tmp_path, domain)]))
    tok = AutoTokenizer.from_pretrained(tiny)
    model = AutoModelForCausalLM.from_pretrained(tiny, dtype=torch.float32).eval()
    same = [(a, {**b, "messages": a["messages"]}) for a, b in pairs]  # b's prompt made a's: nothing to read
    for ma, mb in s.readings(model, tok, same):
        assert abs(ma + mb) < 1e-4
    margins = s.readings(model, tok, pairs)
    summary = s.summary(pairs, margins)
    assert summary["all"]["pairs"] == len(pairs)
    assert summary["all"]["reading"] == pytest.approx(sum(a + b for a, b in margins) / len(margins), abs=1e-3)
    assert all("tea_eggs" in k for k in summary if k != "all")
    assert sum(v["pairs"] for k, v in summary.items() if k != "all") == len(pairs)


def test_answer_rows_group_by_choice_and_bad_rows_are_refused(tmp_path, domain):
    s = bench_script("pair_reading")
    a = {"key": "eggs/eggs.base/x vs y/0", "at": "recipe", "task": "eggs"}
    assert s.distinction(a, dict(a)) == "eggs.base"
    assert s.distinction({"at": "task", "task": "tea_eggs"}, {"at": "task", "task": "cereal"}) == "cereal vs tea_eggs"
    with pytest.raises(SystemExit, match="out of pairs"):
        s.row_pairs([a, {**a, "key": "other"}])
    with pytest.raises(SystemExit, match="odd count"):
        s.row_pairs([a])
    with pytest.raises(SystemExit, match="no such rows file"):
        s.main(["--rows", str(tmp_path / "none.jsonl"), "--model", "student"])
    rows = _rows(tmp_path, domain)
    with pytest.raises(SystemExit, match="no pair's distinction contains 'nothing'"):
        s.main(["--rows", str(rows), "--model", "student", "--only", "nothing"])
    assert json.loads(rows.read_text().splitlines()[0])["at"] == "task"
