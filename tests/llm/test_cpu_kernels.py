"""Packed bfloat16 linear layers on the CPU (llm/cpu_kernels.py): the same numbers as torch's bfloat16
linear layers, and the `bfloat16-weights` dtype (float32 with packed bfloat16 decoder weights)."""

from __future__ import annotations

import pytest

from .conftest import MISSING, SKIP_MODELS


def _packing() -> bool:
    """Whether bfloat16 packing is available (False without the models extra: pytest evaluates every
    skipif condition, so this one must not import torch when the module-level skip applies)."""
    if MISSING:
        return False
    from adaptbench.llm.cpu_kernels import packing_supported

    return packing_supported()


pytestmark = [SKIP_MODELS]
NEEDS_PACKING = pytest.mark.skipif("not _packing()", reason="this CPU or torch build has no bfloat16 oneDNN packing")


@pytest.fixture(scope="module")
def sharp_dir(tiny, tmp_path_factory):
    """The tiny model with weights redrawn at std 0.5 (its greedy output then depends on the context),
    saved: packing happens when a backend loads a model, so the weights must be the saved ones."""
    import shutil

    import torch
    from transformers import AutoModelForCausalLM

    out = tmp_path_factory.mktemp("sharp")
    model = AutoModelForCausalLM.from_pretrained(str(tiny))
    g = torch.Generator().manual_seed(1)
    with torch.no_grad():
        for p in model.parameters():
            if p.dim() == 2:
                p.copy_(torch.randn(p.shape, generator=g) * 0.5)
    model.save_pretrained(out)
    for f in tiny.iterdir():
        if "token" in f.name or f.suffix == ".jinja":
            shutil.copy(f, out / f.name)
    return out


def _actions(domain, backend, steps=4):
    from adaptbench.harness.batches import run_batched
    from adaptbench.harness.rollout import Job
    from adaptbench.llm.policies import LLMPolicy
    from adaptbench.runtime.users import OfflineUser

    jobs = [Job("planner", "juan", t, 0) for t in ("eggs", "cereal")]
    policy = LLMPolicy(backend, domain, "planner", max_tokens=14)
    recs = run_batched(jobs, domain, policy, OfflineUser, batch=1, steps=steps)
    return {(r["task"], r["seed"]): [s["action"] for s in r["steps"]] for r in recs}


@NEEDS_PACKING
def test_packed_bfloat16_linears_give_the_logits_of_torchs_bfloat16_linears(sharp_dir):
    import torch
    from transformers import AutoModelForCausalLM

    from adaptbench.llm.cpu_kernels import PackedLinear, pack_linears

    plain = AutoModelForCausalLM.from_pretrained(str(sharp_dir), dtype=torch.bfloat16).eval()
    packed = AutoModelForCausalLM.from_pretrained(str(sharp_dir), dtype=torch.bfloat16).eval()
    n = pack_linears(packed)
    assert n == 7 * len(packed.model.layers)  # q, k, v, o, gate, up, down in every layer
    assert isinstance(packed.model.layers[0].mlp.down_proj, PackedLinear)
    assert type(packed.lm_head) is torch.nn.Linear  # the output layer stays
    ids = torch.arange(3, 60).view(1, -1)
    with torch.no_grad():
        assert torch.equal(plain(input_ids=ids).logits, packed(input_ids=ids).logits)
        assert torch.equal(plain(input_ids=ids[:, :1]).logits, packed(input_ids=ids[:, :1]).logits)
    assert pack_linears(AutoModelForCausalLM.from_pretrained(str(sharp_dir))) == 0  # float32 stays float32


@NEEDS_PACKING
def test_a_bfloat16_rollout_takes_the_same_actions_packed_or_not(domain, sharp_dir, monkeypatch):
    from adaptbench.llm import cpu_kernels
    from adaptbench.llm.cpu_kernels import PackedLinear
    from adaptbench.llm.hf import TransformersBackend

    packed = TransformersBackend(str(sharp_dir), dtype="bfloat16", batch_size=1)
    assert isinstance(packed.model.model.layers[0].self_attn.q_proj, PackedLinear)
    monkeypatch.setattr(cpu_kernels, "packing_supported", lambda: False)
    plain = TransformersBackend(str(sharp_dir), dtype="bfloat16", batch_size=1)
    assert not isinstance(plain.model.model.layers[0].self_attn.q_proj, PackedLinear)
    got, want = _actions(domain, packed), _actions(domain, plain)
    assert got == want
    assert len({tuple(a) for a in want.values()}) > 1  # the episodes act differently


@NEEDS_PACKING
def test_bfloat16_weights_keep_float32_outside_the_decoder_linears(domain, sharp_dir):
    import torch

    from adaptbench.llm.cpu_kernels import BF16_WEIGHTS, PackedLinear
    from adaptbench.llm.hf import TransformersBackend

    b = TransformersBackend(str(sharp_dir), dtype=BF16_WEIGHTS, batch_size=1)
    full = TransformersBackend(str(sharp_dir), dtype="float32", batch_size=1)
    half = TransformersBackend(str(sharp_dir), dtype="bfloat16", batch_size=1)
    assert b.model.dtype == torch.float32 and b.config()["dtype"] == BF16_WEIGHTS
    assert b.score_dtype() == BF16_WEIGHTS and full.score_dtype() == "float32"
    assert all(isinstance(m, PackedLinear) for m in (b.model.model.layers[-1].mlp.up_proj,
                                                     b.model.model.layers[0].self_attn.o_proj))
    assert b.model.lm_head.weight.dtype == torch.float32
    ids = torch.arange(3, 60).view(1, -1)
    with torch.no_grad():
        got, want = b.model(input_ids=ids).logits, full.model(input_ids=ids).logits
        bf16 = half.model(input_ids=ids).logits.float()
    assert got.dtype == torch.float32 and not torch.equal(got, want)
    # bfloat16 rounding of the weights and of the layers' inputs only: closer to float32 than bfloat16 is
    assert (got - want).abs().mean() < (bf16 - want).abs().mean()
    acts = _actions(domain, b, steps=3)
    assert all(len(a) == 3 for a in acts.values())
    assert b._scorer("float32") is not b.model  # scoring in float32 loads the checkpoint's float32 weights


def test_bfloat16_weights_on_a_cpu_without_packing_is_one_clear_error(sharp_dir, monkeypatch):
    from adaptbench.llm import cpu_kernels
    from adaptbench.llm.hf import TransformersBackend

    monkeypatch.setattr(cpu_kernels, "packing_supported", lambda: False)
    with pytest.raises(ValueError, match="bfloat16-weights needs a CPU with bfloat16 instructions"):
        TransformersBackend(str(sharp_dir), dtype="bfloat16-weights")
