"""The lean pass of one row (llm/one_row.py): the same hidden states and cache as the model's forward."""

from __future__ import annotations

import pytest

from .conftest import SKIP_MODELS

pytestmark = [SKIP_MODELS]


@pytest.mark.parametrize("dtype", ["float32", "bfloat16-weights"])
def test_the_lean_pass_gives_the_forwards_logits_and_cache_bit_for_bit(tiny, dtype):
    import torch

    from adaptbench.llm import decode
    from adaptbench.llm.cpu_kernels import packing_supported
    from adaptbench.llm.hf import TransformersBackend

    if dtype != "float32" and not packing_supported():
        pytest.skip("this CPU or torch build has no bfloat16 oneDNN packing")
    model = TransformersBackend(str(tiny), dtype=dtype).model
    g = torch.Generator().manual_seed(1)
    with torch.no_grad():
        for p in model.parameters():  # sharpened: the random model's activations are near zero
            p.mul_(1 + torch.rand(p.shape, generator=g))
    assert decode.lean(model)
    caches = []
    with torch.no_grad():
        for _ in range(2):
            _, layers = decode.prefill(model, decode.Row(list(range(5, 90)), 16), None, room=16)
            caches.append(decode.cache_of(layers, model.config))
        head = torch.arange(0, model.config.vocab_size, 3)
        for k in range(6):
            got = []
            for lean, cache in zip((False, True), caches, strict=True):
                model.__dict__["_adapt_lean"] = lean
                got.append(decode._forward(model, cache, None, [[7 + k]], [85 + k], 0, head if k % 2 else None)[0])
            assert torch.equal(got[0], got[1])
    assert all(torch.equal(a.keys, b.keys) and torch.equal(a.values, b.values)
               for a, b in zip(caches[0].layers, caches[1].layers, strict=True))
    assert caches[1].get_seq_length() == 85 + 6
