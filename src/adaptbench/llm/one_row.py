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
would.
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
        x = layer.input_layernorm(h)
        shape = (1, 1, -1, attn.head_dim)
        q = attn.q_proj(x).view(shape).transpose(1, 2)
        k = attn.k_proj(x).view(shape).transpose(1, 2)
        v = attn.v_proj(x).view(shape).transpose(1, 2)
        q, k = apply_rotary_pos_emb(q, k, cos, sin)
        k, v = kv.update(k, v)
        o = F.scaled_dot_product_attention(q, k, v, attn_mask=None, dropout_p=0.0, scale=attn.scaling,
                                           is_causal=False, enable_gqa=attn.num_key_value_groups > 1)
        o = o.reshape(1, -1, 1, v.shape[-1]).transpose(1, 2).contiguous()
        h = h + attn.o_proj(o.reshape(1, 1, -1).contiguous())
        h = h + layer.mlp(layer.post_attention_layernorm(h))
    return inner.norm(h)[:, -1]
