"""A decoding pass of one row of a Llama model without transformers' per-call machinery.

    if one_row.supported(model):
        hidden = one_row.step(model, cache, token, position)   # [1, hidden], after the final norm

Decoding one row of a small model on a CPU is dominated by fixed costs per pass: measured on a
30-layer Llama with hidden size 64 (no arithmetic to speak of), one pass through the model's forward
costs ~12 ms of CPU, a third of what SmolLM2-135M's weights take to read. Most of it is the forward's
plumbing, not its arithmetic: keyword routing and deprecation wrappers on every layer, mask
construction, the cache object's dispatch, the attention-function lookup, output dataclasses. `step`
runs the same modules and the same tensor operations in the same order (the layers' norms, linear
layers and MLP are called as modules; rotary embedding, `apply_rotary_pos_emb` and SDPA with grouped
heads as transformers calls them for one unmasked query), so its hidden state is the forward's, bit
for bit (tested), and writes its keys and values into the session's `BufferLayer`s as the forward
would. With packed bfloat16 weights (`cpu_kernels`) it takes the query, key and value projections in
one product and the MLP's gate and up in another (the stacked weights `cpu_kernels` adds).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

TYPES = ("LlamaForCausalLM",)  # models whose decoder layer `step` mirrors (transformers 5.x modeling_llama)


def supported(model) -> bool:
    """Whether `step` computes this model's pass: a Llama causal LM whose attention runs on SDPA."""
    if type(model).__name__ not in TYPES or getattr(model.config, "_attn_implementation", None) != "sdpa":
        return False
    layers = getattr(getattr(model, "model", None), "layers", None)
    return bool(layers) and all(type(layer).__name__ == "LlamaDecoderLayer" for layer in layers)


def step(model, cache, token: int, position: int) -> torch.Tensor:
    """One pass over one token of one row at `position`, its keys and values appended to `cache`'s
    layers; returns the last hidden state after the final norm [1, hidden]."""
    from transformers.models.llama.modeling_llama import apply_rotary_pos_emb

    inner = model.model
    dev = model.device
    h = inner.embed_tokens(torch.tensor([[token]], dtype=torch.long, device=dev))
    cos, sin = inner.rotary_emb(h, torch.tensor([[position]], dtype=torch.long, device=dev))
    for layer, kv in zip(inner.layers, cache.layers, strict=True):
        attn = layer.self_attn
        q, k, v = _qkv(attn, layer.input_layernorm(h))
        q, k = apply_rotary_pos_emb(q, k, cos, sin)
        k, v = kv.update(k, v)
        o = F.scaled_dot_product_attention(q, k, v, attn_mask=None, dropout_p=0.0, scale=attn.scaling,
                                           is_causal=False, enable_gqa=attn.num_key_value_groups > 1)
        o = o.reshape(1, -1, 1, v.shape[-1]).transpose(1, 2).contiguous()
        h = h + attn.o_proj(o.reshape(1, 1, -1).contiguous())
        h = h + _mlp(layer.mlp, layer.post_attention_layernorm(h))
    return inner.norm(h)[:, -1]


def _qkv(attn, x: torch.Tensor) -> tuple:
    """Query, key and value [1, heads, 1, dim] of a normed hidden state: from the projections stacked
    into one product where `cpu_kernels` packed them so, else from each projection."""
    shape = (1, 1, -1, attn.head_dim)
    fused = getattr(attn, "adapt_qkv", None)
    if fused is None:
        parts = attn.q_proj(x), attn.k_proj(x), attn.v_proj(x)
    else:
        parts = fused(x).split([attn.q_proj.out_features, attn.k_proj.out_features, attn.v_proj.out_features], -1)
    return tuple(p.reshape(shape).transpose(1, 2) for p in parts)


def _mlp(mlp, x: torch.Tensor) -> torch.Tensor:
    """The MLP (down(act(gate x) * up x)), gate and up in one product where they were packed so."""
    fused = getattr(mlp, "adapt_gate_up", None)
    if fused is None:
        return mlp(x)
    gate, up = fused(x).chunk(2, dim=-1)
    return mlp.down_proj(mlp.act_fn(gate) * up)
