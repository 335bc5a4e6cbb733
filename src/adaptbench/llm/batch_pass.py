"""Batched passes of a Llama model for the GPU, without transformers' per-call machinery, and CUDA graphs
of the one-token pass.

    if batch_pass.mode(model) != "hf":
        hidden = batch_pass.forward(model, layers, ids, pos, bias)      # [B, hidden], last position
    graphs = batch_pass.graphs_of(model)                                # "graphs" mode: CUDA graphs
    logits = graphs.step(cache, tokens, positions, mask)                # one token per row

The first GPU run (issue 29) found the 135M shape's batched pass at ~75 ms on an H200, where its
weights and cache take under 1 ms to read. Two costs made it: transformers' attention with a padding
mask cannot hand grouped key/value heads to SDPA on CUDA, so it copies every layer's whole cache to
repeat them (`repeat_kv`) each pass; and the forward's plumbing (mask construction, keyword routing,
output objects, ~40 kernel launches a layer) costs milliseconds of CPU per pass while the GPU waits.

`forward` runs the same modules' weights in the same order with three changes: the query heads that
share a key/value head are folded into the query length (a query [B, heads, L, d] is read as
[B, kv heads, groups x L, d]: SDPA then needs no repeated cache and serves masks with its
memory-efficient kernel); one additive mask per pass (`attention_bias`), shared by every layer; and the
query/key/value and gate/up projections stacked (`Stacked`: two products where there were five). Its
hidden states equal the model forward's up to rounding (tested on the CPU in float32).

`DecodeGraphs` keeps one key/value pool per model ([layers, 2, rows, kv heads, capacity, d], allocated
once) that a decode call's batch cache lives in, and captures the decoding pass for each (rows,
length, new tokens) bucket once: each rounded up to a power of two (the rows past the batch compute
garbage nobody reads), the positions past a row's cache and a row's padding masked. The pool also keeps
which of its positions are real (`real`), so a pass's additive mask is made inside the graph: a
pass's CPU work is one copy of its ids and positions from pinned memory and one replay, which
launches the whole pass (one CPU call for ~1,000 kernels). A session keeps its row of the pool as one `PackedRow` copy.
Reading a step's new prompt tokens (`decode.prefill_many`) runs `forward` on the same pool.
"""

from __future__ import annotations

import os

import numpy as np
import torch
import torch.nn.functional as F

from . import one_row
from .kv_buffer import BufferLayer, PackedRow, as_layers

MODES = ("hf", "lean", "graphs")  # the model's forward; `forward`; `forward` plus CUDA graphs of one-token passes
MODE_ENV = "ADAPT_DECODE_PASS"  # overrides the device's default (for tests and benchmarks)


def default_mode(model) -> str:
    """`graphs` on a GPU for a Llama model whose attention runs on SDPA, `hf` otherwise (the CPU has
    its own fast paths: `one_row`, `cpu_kernels`); ADAPT_DECODE_PASS overrides where the model allows
    (`graphs` off CUDA keeps the pool and runs its passes eagerly: how the CPU tests check them)."""
    want = os.environ.get(MODE_ENV)
    if not one_row.supported(model):
        return "hf"
    if want in MODES:
        return want
    return "graphs" if model.device.type == "cuda" else "hf"


def mode(model) -> str:
    """The model's decoding pass (`MODES`), decided once per model (`set_mode` changes it)."""
    hit = model.__dict__.get("_adapt_pass")
    if hit is None:
        hit = model.__dict__["_adapt_pass"] = default_mode(model)
    return hit


def set_mode(model, name: str) -> None:
    """Use this decoding pass for the model from now on (`graphs` off CUDA: the pool, passes run eagerly)."""
    if name not in MODES:
        raise ValueError(f"unknown decoding pass '{name}' (choose from: {', '.join(MODES)})")
    if name != "hf" and not one_row.supported(model):
        name = "hf"
    model.__dict__["_adapt_pass"] = name


class Stacked:
    """A layer's query/key/value and gate/up weights stacked into one product each (biases too, where
    the model has them)."""

    def __init__(self, layer):
        attn, mlp = layer.self_attn, layer.mlp
        qkv = (attn.q_proj, attn.k_proj, attn.v_proj)
        self.qkv_w = torch.cat([m.weight for m in qkv])
        self.qkv_b = None if qkv[0].bias is None else torch.cat([m.bias for m in qkv])
        self.split = [m.out_features for m in qkv]
        gu = (mlp.gate_proj, mlp.up_proj)
        self.gu_w = torch.cat([m.weight for m in gu])
        self.gu_b = None if gu[0].bias is None else torch.cat([m.bias for m in gu])


def stacked(model) -> list:
    """The model's `Stacked` weights per layer (made once, kept on the model)."""
    hit = model.__dict__.get("_adapt_stacked")
    if hit is None:
        with torch.no_grad():
            hit = model.__dict__["_adapt_stacked"] = [Stacked(layer) for layer in model.model.layers]
    return hit


def attention_bias(mask: torch.Tensor, new: int, dtype) -> torch.Tensor:
    """The additive attention mask [B, 1, new, T] of a pass over `new` tokens per row: `mask` [B, T]
    (1: a real position; the last `new` columns are the pass's own tokens) and causal among the new
    ones; 0 where allowed, the dtype's minimum elsewhere. Stored in a buffer whose rows are a multiple
    of 16 elements wide (SDPA's memory-efficient kernel copies a mask that is not)."""
    b, t = mask.shape
    keys = mask.bool()[:, None, :].expand(b, new, t)
    causal = torch.ones((new, t), dtype=torch.bool, device=mask.device).tril(t - new)
    allowed = keys & causal
    out = torch.empty((b, 1, new, -(-t // 16) * 16), dtype=dtype, device=mask.device)[..., :t]
    out.copy_(torch.where(allowed, 0.0, torch.finfo(dtype).min).unsqueeze(1))
    return out


def grouped_bias(bias, heads: int, kv_heads: int, new: int):
    """`attention_bias` [B, 1, L, T] repeated for the query heads folded into the query length (`_attend`):
    [B, 1, groups x L, T]; once per pass, not per layer (None and one-token passes need no repeat)."""
    groups = heads // kv_heads
    if bias is None or groups == 1 or new == 1:
        return bias
    return bias.repeat(1, 1, groups, 1)


def _attend(attn, q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, bias) -> torch.Tensor:
    """SDPA with the query heads that share a key/value head folded into the query length: q [B, H, L,
    d], k and v [B, Hkv, T, d], bias [B, 1, groups x L, T] (`grouped_bias`; [B, 1, 1, T] for one
    token) or None; returns [B, L, H * d]."""
    b, h, n, d = q.shape
    q = q.reshape(b, k.shape[1], h // k.shape[1] * n, d)
    o = F.scaled_dot_product_attention(q, k, v, attn_mask=bias, dropout_p=0.0, scale=attn.scaling)
    return o.reshape(b, h, n, d).transpose(1, 2).reshape(b, n, h * d)


def _layer(layer, w: Stacked, h: torch.Tensor, cos, sin, write, bias) -> torch.Tensor:
    """One decoder layer over h [B, L, hidden]; `write(k, v)` stores the new keys and values and returns
    the keys and values to attend to."""
    from transformers.models.llama.modeling_llama import apply_rotary_pos_emb

    attn, mlp = layer.self_attn, layer.mlp
    b, n, _ = h.shape
    qkv = F.linear(layer.input_layernorm(h), w.qkv_w, w.qkv_b).split(w.split, dim=-1)
    q, k, v = (x.view(b, n, -1, attn.head_dim).transpose(1, 2) for x in qkv)
    q, k = apply_rotary_pos_emb(q, k, cos, sin)
    k, v = write(k, v)
    h = h + attn.o_proj(_attend(attn, q, k, v, bias))
    gate, up = F.linear(layer.post_attention_layernorm(h), w.gu_w, w.gu_b).chunk(2, dim=-1)
    return h + mlp.down_proj(mlp.act_fn(gate) * up)


def forward(model, layers: list, ids: torch.Tensor, pos: torch.Tensor, bias) -> torch.Tensor:
    """One pass over ids [B, L] at positions pos [B, L], the new keys and values written into `layers`
    (`kv_buffer.BufferLayer`s, in place); `bias`: `attention_bias` (None: every cached position is real
    and L is 1). Returns the last position's hidden state after the final norm [B, hidden]."""
    inner = model.model
    h = inner.embed_tokens(ids)
    cos, sin = inner.rotary_emb(h, pos)
    if bias is None and ids.shape[1] > 1:
        t = layers[0].get_seq_length() + ids.shape[1]
        bias = attention_bias(torch.ones((ids.shape[0], t), dtype=torch.long, device=ids.device), ids.shape[1],
                              h.dtype)
    bias = _grouped(model, bias, ids.shape[1])
    for layer, w, kv in zip(inner.layers, stacked(model), layers, strict=True):
        h = _layer(layer, w, h, cos, sin, kv.update, bias)
    return inner.norm(h)[:, -1]


def _grouped(model, bias, new: int):
    """`grouped_bias` for the model's heads."""
    cfg = model.config
    return grouped_bias(bias, cfg.num_attention_heads, cfg.num_key_value_heads or cfg.num_attention_heads, new)


def right_aligned(chunks: list, starts: list, pad_id: int, width: int | None = None) -> tuple:
    """Rows' new tokens right-aligned and left-padded to the longest (or `width`): (ids, position ids
    from each row's `start`, attention-mask tail with 0 on the padding), each [B, longest] int64, on the
    CPU (built in numpy: one pass per decoding token calls this for every row)."""
    lens = np.fromiter((len(c) for c in chunks), dtype=np.int64, count=len(chunks))
    most = width or int(lens.max())
    first = most - lens  # each row's first real column
    col = np.arange(most, dtype=np.int64)
    real = col[None, :] >= first[:, None]
    ids = np.full((len(chunks), most), pad_id, dtype=np.int64)
    ids[real] = np.fromiter((t for c in chunks for t in c), dtype=np.int64, count=int(lens.sum()))
    pos = np.where(real, np.asarray(starts, dtype=np.int64)[:, None] + col[None, :] - first[:, None], 0)
    return torch.from_numpy(ids), torch.from_numpy(pos), torch.from_numpy(real.astype(np.int64))


ROWS_MIN, LENGTH_MIN = 1, 256  # the smallest buckets
LONGEST = 32  # the most new tokens per row a graphed pass reads (a longer pass runs `forward`)


def bucket(n: int, least: int) -> int:
    """The power of two at least `n` and `least`."""
    return max(least, 1 << max(0, n - 1).bit_length())


class DecodeGraphs:
    """A model's key/value pool and its captured one-token passes (see the module's docstring). `rows`
    and `capacity` (positions) size the pool; a batch that does not fit decodes on its own buffers
    through `forward`. Off CUDA the passes run eagerly (the same arithmetic: how the CPU tests check it)."""

    def __init__(self, model, rows: int, capacity: int):
        self.model, self.rows, self.capacity = model, rows, capacity
        cfg, dev, dtype = model.config, model.device, model.dtype
        heads = cfg.num_key_value_heads or cfg.num_attention_heads
        dim = getattr(cfg, "head_dim", None) or cfg.hidden_size // cfg.num_attention_heads
        self.kv = torch.zeros((len(model.model.layers), 2, rows, heads, capacity, dim), dtype=dtype, device=dev)
        self.k = [self.kv[i, 0] for i in range(self.kv.shape[0])]  # per layer [rows, heads, capacity, dim]
        self.v = [self.kv[i, 1] for i in range(self.kv.shape[0])]
        # a pass's inputs: ids, positions and the new columns' realness [3, rows, LONGEST], and the pass's
        # first cache column (at [1, 0, LONGEST]), written on the host (pinned on CUDA) and copied in once
        self.host = torch.zeros((3, rows, LONGEST + 1), dtype=torch.long, pin_memory=dev.type == "cuda")
        self.staged = torch.zeros((3, rows, LONGEST + 1), dtype=torch.long, device=dev)
        self.ids, self.pos, self.tail = (self.staged[i, :, :LONGEST] for i in range(3))
        self.cols = torch.zeros((LONGEST,), dtype=torch.long, device=dev)
        self.span = torch.arange(capacity, device=dev)
        self.real = torch.zeros((rows, capacity), dtype=torch.bool, device=dev)  # which cache positions are real
        self.copied = torch.cuda.Event() if dev.type == "cuda" else None  # the last copy of `host` is done
        self.out: dict = {}  # (rows, length, width) -> logits [rows, V] the graph writes
        self.graphs: dict = {}  # (rows, length, width) -> torch.cuda.CUDAGraph
        self.pool = torch.cuda.graph_pool_handle() if dev.type == "cuda" else None
        self.captures = 0

    def fits(self, rows: int, positions: int) -> bool:
        """Whether a batch of `rows` rows with `positions` positions each fits the pool."""
        return rows <= self.rows and positions <= self.capacity

    def adopt(self, layers: list) -> list:
        """The batch cache's layers moved into the pool: `PoolLayer`s over its first rows (one copy)."""
        out = []
        for layer, pk, pv in zip(layers, self.k, self.v, strict=True):
            b, n = layer.keys.shape[0], layer.get_seq_length()
            pk[:b, :, :n] = layer.keys
            pv[:b, :, :n] = layer.values
            out.append(PoolLayer(pk, pv, b, n))
        return out

    def stack(self, rows_layers: list, lengths: list) -> tuple:
        """The rows' caches (`PackedRow`s or per-layer lists) left-padded to one width in the pool's first
        rows: one copy per packed row; returns (`PoolLayer`s, attention mask [B, width])."""
        width, dev = max(lengths), self.kv.device
        for r, (cached, n) in enumerate(zip(rows_layers, lengths, strict=True)):
            if isinstance(cached, PackedRow):
                self.kv[:, :, r, :, width - n:width] = cached.data[:, :, :, :n]
                continue
            for layer, pk, pv in zip(as_layers(cached), self.k, self.v, strict=True):
                pk[r, :, width - n:width] = layer.keys[0, :, :n]
                pv[r, :, width - n:width] = layer.values[0, :, :n]
        mask = torch.zeros((len(lengths), width), dtype=torch.long)
        for r, n in enumerate(lengths):
            mask[r, width - n:] = 1
        b = len(lengths)
        return [PoolLayer(pk, pv, b, width) for pk, pv in zip(self.k, self.v, strict=True)], mask.to(dev)

    def packed(self, k: int, where, n: int) -> PackedRow:
        """Row k's cached positions (`where`, on the CPU: its real ones; None: the first `n`) of every
        layer, copied out as one `PackedRow`."""
        if where is None:
            return PackedRow(self.kv[:, :, k, :, :n].clone())
        return PackedRow(self.kv[:, :, k].index_select(3, where.to(self.kv.device)))

    def takes(self, layers: list, most: int) -> bool:
        """Whether a pass of at most `most` new tokens a row runs as a graph: the layers are this pool's
        and the pass's columns (`most` rounded up to a power of two) fit after their positions."""
        return (most <= LONGEST and self.holds(layers)
                and layers[0].get_seq_length() + bucket(most, 1) <= self.capacity)

    def holds(self, layers: list) -> bool:
        """Whether these layers are this pool's (still: a layer that outgrew it left)."""
        return all(isinstance(x, PoolLayer) and x.pooled(pk) for x, pk in zip(layers, self.k, strict=True))

    def step(self, layers: list, new: list, starts: list, mask) -> tuple:
        """A pass over each row's new tokens (`new`: 1 to `LONGEST` per row, right-aligned and padded
        to a power of two), row r's first at position `starts[r]`, over the pool's layers; `mask` [B, n]
        of the cached positions (None: all real). Returns (logits [B, V] (float32; a view valid until
        the next step), the mask after the pass: None while no position is padding, else a view of the
        pool's `real` positions, valid until the next step)."""
        b, n = len(new), layers[0].get_seq_length()
        width = bucket(max(len(t) for t in new), 1)
        key = (min(bucket(b, ROWS_MIN), self.rows), min(bucket(n + width, LENGTH_MIN), self.capacity), width)
        padded = self._inputs(key, new, starts, mask, n)
        if key not in self.out:
            self._capture(key)
        elif self.pool is not None:
            self.graphs[key].replay()
        else:
            self.out[key] = self._pass(*key)
        for layer in layers:
            layer.grew(width)
        after = self.real[:b, :n + width] if mask is not None or padded else None
        return self.out[key][:b], after

    def _inputs(self, key, new: list, starts: list, mask, n: int) -> bool:
        """Write a pass's inputs into the graphs' static tensors (one copy from the host) and the cached
        positions' realness into `real`; returns whether any new column is padding."""
        rows, length, width = key
        b = len(new)
        ids, pos, tail = right_aligned(new, starts, 0, width)
        host = self.host
        if self.copied is not None:
            self.copied.synchronize()  # the previous pass's inputs have left the host buffer
        host[0, :b, :width], host[1, :b, :width], host[2, :b, :width] = ids, pos, tail
        host[:, b:rows, :width] = 0
        host[1, 0, LONGEST] = n
        self.staged[:, :rows].copy_(host[:, :rows], non_blocking=True)
        if self.copied is not None:
            self.copied.record()
        if mask is None:
            self.real[:b, :n] = True
        elif mask.data_ptr() != self.real.data_ptr() or mask.stride() != self.real[:b, :n].stride():
            self.real[:b, :n] = mask.to(self.real.device).bool()
        return not bool(tail.all())

    def _pass(self, rows: int, length: int, width: int) -> torch.Tensor:
        """The pass over `width` new tokens of the pool's first `rows` rows attending to `length`
        positions: the new columns' realness and the additive mask are made inside it, from `staged`."""
        model, inner = self.model, self.model.model
        cols = self.cols[:width]
        torch.add(self.span[:width], self.staged[1, 0, LONGEST], out=cols)
        self.real[:rows].index_copy_(1, cols, self.tail[:rows, :width].bool())
        allowed = self.real[:rows, None, None, :length] & (self.span[:length] <= cols[:, None])
        bias = torch.where(allowed, 0.0, torch.finfo(model.dtype).min).to(model.dtype)
        bias = _grouped(model, bias, width)
        h = inner.embed_tokens(self.ids[:rows, :width])
        cos, sin = inner.rotary_emb(h, self.pos[:rows, :width])
        for layer, w, pk, pv in zip(inner.layers, stacked(model), self.k, self.v, strict=True):
            h = _layer(layer, w, h, cos, sin, _writer(pk[:rows], pv[:rows], cols, length), bias)
        return model.get_output_embeddings()(inner.norm(h)[:, -1]).float()

    def _capture(self, key) -> None:
        """Run the pass for this bucket (its output is this step's) and, on CUDA, capture it for replay."""
        if self.pool is None:
            self.out[key] = self._pass(*key)
            return
        stream = torch.cuda.Stream()
        stream.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(stream):
            self._pass(*key)  # warm-up on a side stream, as capture asks (writes the same cache column)
        torch.cuda.current_stream().wait_stream(stream)
        graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(graph, pool=self.pool, capture_error_mode="thread_local"):
            self.out[key] = self._pass(*key)
        graph.replay()
        self.graphs[key] = graph
        self.captures += 1


def _writer(pk: torch.Tensor, pv: torch.Tensor, cols: torch.Tensor, length: int):
    def write(k, v):
        pk.index_copy_(2, cols, k)
        pv.index_copy_(2, cols, v)
        return pk[:, :, :length], pv[:, :, :length]

    return write


def graphs_of(model, rows: int, positions: int, lane: int = 0) -> DecodeGraphs | None:
    """The model's `DecodeGraphs` for this lane (`lanes.run` decodes lanes in turn, each in a pool of its
    own) sized for at least `rows` rows of `positions` positions (made, or remade larger, here: a new
    pool drops the old one's graphs), or None when the model does not decode through graphs."""
    if mode(model) != "graphs":
        return None
    name = "_adapt_graphs" if lane == 0 else f"_adapt_graphs{lane}"
    have = model.__dict__.get(name)
    if have is not None and have.fits(rows, positions):
        return have
    rows = max(bucket(rows, ROWS_MIN), have.rows if have else 0)
    capacity = max(bucket(positions, 1024), have.capacity if have else 0)
    model.__dict__[name] = None  # the old pool is freed before the new one is allocated
    made = model.__dict__[name] = DecodeGraphs(model, rows, capacity)
    return made


class PoolLayer(BufferLayer):
    """A batch cache layer whose buffer is the first `rows` rows of a `DecodeGraphs` pool (written in
    place by graph replays and by `forward`); copies out what a session keeps, and compacts in place.
    Its `keys` and `values` are sliced when read (a replay only counts its positions: `grew`)."""

    keys = property(lambda self: self._k[:, :, :self.n], lambda self, value: None)
    values = property(lambda self: self._v[:, :, :self.n], lambda self, value: None)

    def __init__(self, pk: torch.Tensor, pv: torch.Tensor, rows: int, n: int):
        super().__init__(pk[:rows], pv[:rows], adopt=True)
        self._pk, self._pv = pk, pv
        self.n = n

    def pooled(self, pk: torch.Tensor) -> bool:
        """Whether this layer still lives in that pool."""
        return self._pk is pk and self._k.data_ptr() == pk.data_ptr()

    def grew(self, q: int) -> None:
        """A graph replay wrote `q` more positions."""
        self.n += q

    def select(self, rows: torch.Tensor) -> None:
        """Keep only these batch rows, moved to the pool's first rows."""
        if not self.pooled(self._pk):
            return super().select(rows)
        k, v = self._k[rows], self._v[rows]
        self._pk[:len(rows)] = k
        self._pv[:len(rows)] = v
        self._k, self._v = self._pk[:len(rows)], self._pv[:len(rows)]
        return None

    def row(self, k: int, where):
        """Row k's cached positions as a layer of its own: always a copy (the pool is reused)."""
        if where is None:
            return BufferLayer(self.keys[k:k + 1], self.values[k:k + 1])
        where = where.to(self.keys.device)
        return BufferLayer(self.keys[k:k + 1, :, where], self.values[k:k + 1, :, where], adopt=True)
