"""Linear layers with packed bfloat16 weights on a CPU with bfloat16 instructions.

    n = pack_linears(model)                  # a bfloat16 model: the same numbers, faster products
    n = pack_linears(model, keep_dtype=True) # a float32 model: bfloat16 weights, everything else float32

A transformer decoding one row reads every weight once per token, so a step's time is mostly the
matrix-vector products of its linear layers. torch's `F.linear` on bfloat16 weights takes a generic
path on the CPU; oneDNN's linear with the weight reordered once into its blocked layout
(`torch.ops.mkldnn._reorder_linear_weight`, the kernel `torch.compile` uses on CPUs after freezing)
computes the same products (bitwise, tested) faster: measured on this project's 2-core AMD EPYC
(AVX512-BF16), 24 SmolLM2 MLP matrices (1,536 x 576), 1 thread: one row 4.4 ms packed against 6.5 ms
for `F.linear` in bfloat16 and 7.9 ms in float32; 400 rows 124 / 131 / 195 ms.

`keep_dtype`: the model stays float32 (norms, residual stream, rotary embeddings, attention, the
key/value cache and the output layer) and only its decoder layers' linear weights are bfloat16: a
layer's input is rounded to bfloat16 and its output (accumulated in float32, rounded to bfloat16)
returned as float32. That is the backend's `--dtype bfloat16-weights`: the weight bytes of bfloat16
with float32 attention (torch's SDPA is several times slower in bfloat16 than in float32 for one
query row on this CPU: 3.1 ms against 0.5 ms a layer at 3,000 positions).
"""

from __future__ import annotations

from functools import lru_cache

import torch

BF16_WEIGHTS = "bfloat16-weights"  # the backend dtype: a float32 model whose decoder linear weights are packed bfloat16


@lru_cache(maxsize=1)
def packing_supported() -> bool:
    """Whether this torch build packs bfloat16 linear weights for oneDNN and the CPU computes in bfloat16."""
    try:
        ops = torch.ops.mkldnn
        return (torch.backends.mkldnn.is_available() and hasattr(ops, "_linear_pointwise")
                and hasattr(ops, "_reorder_linear_weight") and bool(ops._is_mkldnn_bf16_supported()))
    except (AttributeError, RuntimeError):
        return False


class PackedLinear(torch.nn.Module):
    """A linear layer whose weight is bfloat16 in oneDNN's blocked layout (reordered once); given
    several layers of one input, their weights stacked (one product for all: their outputs side by
    side). Its input is rounded to bfloat16; the output comes back in the input's dtype. Inference
    only (no gradient reaches the packed weight)."""

    def __init__(self, *linears: torch.nn.Linear):
        super().__init__()
        self.in_features = linears[0].in_features
        self.out_features = sum(lin.out_features for lin in linears)
        weight = torch.cat([lin.weight.detach() for lin in linears]).to(torch.bfloat16)
        self.register_buffer("packed", torch.ops.mkldnn._reorder_linear_weight(weight, 1), persistent=False)
        biases = [lin.bias for lin in linears]
        bias = None if all(b is None for b in biases) else torch.cat(
            [b.detach() if b is not None else lin.weight.new_zeros(lin.out_features)
             for b, lin in zip(biases, linears, strict=True)]).to(torch.bfloat16)
        self.register_buffer("bias", bias, persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """x [..., in] -> [..., out] in x's dtype."""
        flat = x.reshape(-1, self.in_features).to(torch.bfloat16)
        out = torch.ops.mkldnn._linear_pointwise(flat, self.packed, self.bias, "none", [], "")
        return out.view(*x.shape[:-1], self.out_features).to(x.dtype)

    def extra_repr(self) -> str:
        return f"in_features={self.in_features}, out_features={self.out_features}, packed bfloat16"


def pack_linears(model, keep_dtype: bool = False) -> int:
    """Replace the `nn.Linear` layers inside the model's decoder layers (`model.model.layers`; the
    output layer and embeddings stay) by `PackedLinear`s, on a CPU where `packing_supported()`; a
    bfloat16 model only, unless `keep_dtype` (a float32 model keeps float32 outside these layers).
    Returns how many were replaced (0: nothing changed)."""
    layers = getattr(getattr(model, "model", None), "layers", None)
    if layers is None or model.device.type != "cpu" or not packing_supported():
        return 0
    if model.dtype != torch.bfloat16 and not keep_dtype:
        return 0
    for layer in layers:
        _fuse(layer)
    n = 0
    for parent in layers.modules():
        for name, child in list(parent.named_children()):
            if type(child) is torch.nn.Linear:
                setattr(parent, name, PackedLinear(child))
                n += 1
    return n


FUSED = ("adapt_qkv", "adapt_gate_up")  # what `_fuse` adds: the attention's q, k, v and the MLP's gate, up stacked


def _fuse(layer) -> None:
    """Give a Llama-style decoder layer stacked packed weights for `one_row.step`: one product for the
    query, key and value projections (`self_attn.adapt_qkv`) and one for the MLP's gate and up
    projections (`mlp.adapt_gate_up`): a oneDNN call costs ~15 us of fixed overhead (measured, one
    row), 210 a token for SmolLM2's 30 layers unfused, 120 fused. The layer's own modules stay (the
    forward over a prompt uses them), so these weights are held twice."""
    attn, mlp = getattr(layer, "self_attn", None), getattr(layer, "mlp", None)
    qkv = [getattr(attn, n, None) for n in ("q_proj", "k_proj", "v_proj")]
    gate_up = [getattr(mlp, n, None) for n in ("gate_proj", "up_proj")]
    if all(type(m) is torch.nn.Linear for m in qkv):
        attn.adapt_qkv = PackedLinear(*qkv)
    if all(type(m) is torch.nn.Linear for m in gate_up) and hasattr(mlp, "down_proj") and hasattr(mlp, "act_fn"):
        mlp.adapt_gate_up = PackedLinear(*gate_up)
