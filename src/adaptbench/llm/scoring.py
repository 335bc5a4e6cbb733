"""Scoring continuations of one prompt with a transformers model: the prompt is read once, and every
continuation is read after its keys and values.

    first, layers = read_prompt(model, prompt_ids)              # one forward pass over the prompt
    logprobs = score_after(model, first, layers, len(prompt_ids), [ids_a, ids_b, ...], pad_id)

Scoring used to put the prompt in front of every continuation and pad the batch: B continuations of a
P-token prompt cost B x (P + C) token positions, so a batch was no faster than one call per
continuation (0.35x measured). Here the prompt costs P positions once and each continuation C: its
first token's log-probability comes from the prompt's last logits, the others from one batched pass
over the continuations (right-padded: a real token never sees the padding after it, so no mask is
needed) that attends to the prompt's cache, expanded to the batch without a copy (`PrefixLayer`).
"""

from __future__ import annotations

import torch
from transformers import DynamicCache
from transformers.cache_utils import DynamicLayer

from .decode import cache_arg


class PrefixLayer(DynamicLayer):
    """One layer's prompt keys and values shared by a batch of continuations: a pass attends to the
    prompt (broadcast to the batch, not copied) followed by its own new positions, which are not kept
    (each batch of continuations starts again from the prompt)."""

    def __init__(self, keys: torch.Tensor, values: torch.Tensor, batch: int):
        super().__init__()
        self.keys, self.values = keys.expand(batch, -1, -1, -1), values.expand(batch, -1, -1, -1)
        self.dtype, self.device, self.is_initialized = keys.dtype, keys.device, True

    def update(self, key_states: torch.Tensor, value_states: torch.Tensor, *args, **kwargs) -> tuple:
        """The prompt's keys and values followed by the pass's own (the cache itself is unchanged)."""
        return torch.cat([self.keys, key_states], dim=-2), torch.cat([self.values, value_states], dim=-2)


def read_prompt(model, prompt: list) -> tuple:
    """One forward pass over the prompt's ids: (log-probabilities after its last token [V], float32;
    per-layer (keys, values) of shape [1, heads, P, dim])."""
    if not prompt:
        raise ValueError("scoring needs a prompt of at least one token")
    ids = torch.tensor([prompt], dtype=torch.long, device=model.device)
    cache = DynamicCache(config=model.config)
    out = model(input_ids=ids, use_cache=True, logits_to_keep=1, **cache_arg(model, cache))
    return torch.log_softmax(out.logits[0, -1].float(), dim=-1), [(layer.keys, layer.values) for layer in cache.layers]


def score_after(model, first: torch.Tensor, layers: list, start: int, conts: list, pad_id: int = 0) -> list:
    """Per-token log-probabilities (tuples of floats) of each continuation (a list of ids) after a
    prompt read by `read_prompt` (`start`: its length): the first token from `first`, the others from
    one pass over every continuation but its last token, at positions `start`, `start + 1`, ..."""
    out = [[first[c[0]].item()] if c else [] for c in conts]
    width = max((len(c) - 1 for c in conts), default=0)
    if width <= 0:
        return [tuple(x) for x in out]
    ids = torch.full((len(conts), width), pad_id, dtype=torch.long)
    for i, c in enumerate(conts):
        if len(c) > 1:
            ids[i, :len(c) - 1] = torch.tensor(c[:-1], dtype=torch.long)
    dev = model.device
    cache = DynamicCache(config=model.config)
    cache.layers = [PrefixLayer(k, v, len(conts)) for k, v in layers]
    pos = torch.arange(start, start + width, device=dev)
    logits = model(input_ids=ids.to(dev), position_ids=pos.expand(len(conts), -1), cache_position=pos,
                   use_cache=True, **cache_arg(model, cache)).logits.float()
    for i, c in enumerate(conts):
        if len(c) > 1:
            rows = logits[i, :len(c) - 1]
            picked = rows.gather(-1, torch.tensor(c[1:], dtype=torch.long, device=rows.device).unsqueeze(-1))
            out[i] += (picked.squeeze(-1) - torch.logsumexp(rows, dim=-1)).tolist()
    return [tuple(x) for x in out]
