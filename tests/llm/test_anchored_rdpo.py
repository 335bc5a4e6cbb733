"""`bench/anchored_rdpo.py`: its completion scores are those of the whole sequence, the DPO term is log 2
where the model is its reference, a masked token counts nowhere, and "no DPO" is the chosen side's loss."""

from __future__ import annotations

import math

from .bench_scripts import bench_script
from .conftest import SKIP_MODELS

pytestmark = SKIP_MODELS


def _script():
    """The bench script as a module."""
    return bench_script("anchored_rdpo")


def _models(tiny):
    import torch
    from transformers import AutoModelForCausalLM

    return [AutoModelForCausalLM.from_pretrained(tiny, dtype=torch.float32).eval() for _ in range(2)]


def _row(keep=None):
    from adaptbench.training.trainers.encode import Encoded

    key = ("p", "eggs", 100, 0, 1)
    return Encoded(key, tuple(range(5, 40)), (41, 42, 43), (44, 45), chosen_keep=keep,
                   rejected_keep=None if keep is None else (1, 1))


def test_completion_scores_are_the_whole_sequences(tiny):
    import torch

    model, _ = _models(tiny)
    row = _row()
    lc, lr = _script().completion_logprobs(model, row.prompt, [row.chosen, row.rejected])
    for part, got in ((row.chosen, lc), (row.rejected, lr)):
        ids = torch.tensor([list(row.prompt) + list(part)])
        with torch.no_grad():
            logp = model(input_ids=ids).logits[0].log_softmax(-1)
        n = len(row.prompt)
        whole = sum(float(logp[n - 1 + i, t]) for i, t in enumerate(part))
        assert abs(float(got.detach().sum()) - whole) < 1e-3


def test_dpo_term_is_log_two_at_the_reference_and_sft_is_the_chosen_loss(tiny):
    model, anchor = _models(tiny)
    s = _script()
    rows = [_row()]
    (term,), _ = s.row_terms("no-reflection", model, anchor, rows, [0], {}, 0.1)
    assert abs(float(term.detach()) - math.log(2)) < 1e-4
    (sft,), right = s.row_terms("sft", model, anchor, rows, [0], {}, 0.1)
    (lc,) = s.completion_logprobs(model, rows[0].prompt, [rows[0].chosen])
    assert right == 0 and abs(float(sft.detach()) + float(lc.detach().mean())) < 1e-5
    (dpo,), _ = s.row_terms("dpo", model, anchor, rows, [0], {}, 0.1)
    assert abs(float(dpo.detach()) - (math.log(2) + float(sft.detach()))) < 1e-4


def test_a_masked_token_counts_nowhere(tiny):
    import torch

    model, _ = _models(tiny)
    s = _script()
    full = _row()
    masked = _row(keep=(1, 0, 1))
    (sft_masked,), _ = s.row_terms("sft", model, None, [masked], [0], {}, 0.1)
    (lc,) = s.completion_logprobs(model, full.prompt, [full.chosen])
    expected = -(lc[0] + lc[2]) / 2
    assert torch.isclose(sft_masked.detach(), expected.detach(), atol=1e-5)


def _args(**over):
    import argparse

    s = _script()
    base = dict(out="", model="m", data=["d"], method="dpo", episodes=["e.jsonl"], rows_per_update=4,
                episodes_per_update=2, anchor_kl=10.0, beta=0.1, lr=1e-3, mask_forced=True, seed=0)
    assert set(base) - {"out"} == set(s.SETTINGS)
    return argparse.Namespace(**(base | over))


def test_a_rerun_resumes_after_the_last_whole_save_and_cuts_its_curve(tmp_path):
    import json

    import pytest

    s = _script()
    out = tmp_path / "run"
    assert s.resume_point(out, _args()) == 0
    for step in (100, 200):
        (out / f"model-{step}").mkdir()
        (out / f"model-{step}" / "optimizer.pt").write_bytes(b"")
    (out / "model-300.partial").mkdir()  # killed while saving
    (out / "curve.jsonl").write_text("".join(json.dumps({"step": k}) + "\n" for k in range(10, 260, 10)))
    assert s.resume_point(out, _args()) == 200
    assert [json.loads(x)["step"] for x in (out / "curve.jsonl").read_text().splitlines()][-1] == 200
    with pytest.raises(SystemExit, match="lr"):
        s.resume_point(out, _args(lr=3e-4))


def test_several_data_folders_are_read_in_order_and_an_unfinished_one_is_named(tiny, tmp_path):
    import pytest
    from transformers import AutoTokenizer

    from .test_trainers import _messages, _pairs, _row

    s = _script()
    tok = AutoTokenizer.from_pretrained(tiny)
    _pairs(tmp_path / "a", [_row(0, "teacher", _messages(3)), _row(1, "question", _messages(3), chosen='Ask "Cheese?"')])
    _pairs(tmp_path / "b", [_row(2, "teacher", _messages(3))])
    folders = [str(tmp_path / "a"), str(tmp_path / "b")]
    assert [r.key[-1] for r in s.method_rows("dpo", folders, tok, mask=False)] == [0, 1, 2]
    assert [r.key[-1] for r in s.method_rows("sft", folders[::-1], tok, mask=False)] == [2, 0, 1]
    (tmp_path / "b" / "summary.json").unlink()
    with pytest.raises(SystemExit, match=r"b: `adapt train data` has not finished"):
        s.method_rows("dpo", folders, tok, mask=False)
