"""The transformers backend's generation loop: batched decoding under per-row grammars, with each
episode's key/value cache kept between its steps.

    sessions = Sessions(limit=32)
    rows = [Row(prompt_ids, max_tokens=24, session="planner/juan/eggs/0"), ...]
    decode(model, rows, sessions, Picker(grammar_processor_or_None), stopped)   # fills row.tokens

An agent's prompt at step t+1 is its prompt at step t, the action it generated and one more turn
(unless left-truncation dropped old history), so re-reading the whole prompt each step — what
`model.generate` does — costs O(steps x prompt) per episode and dominates a small model's time. Here
each row first reads only the tokens after the longest prefix it shares with its session's cached
tokens (one forward pass per row over the new suffix), then all rows decode together: the rows'
caches are left-padded into one batch cache, every step is one forward pass over each running row's
new tokens with explicit position ids, and a row leaves the batch when it stops. A row's cache (prompt and
generated tokens) is stored back under its session for the next step; `Sessions` keeps the most
recently used `limit` of them.

The grammar acts between passes: after a row takes a token its matcher is fed and its next mask
computed, and while that mask allows a single token (a literal the grammar spells out, EOS after a
complete action) the row takes it without a pass of its own; a row's tokens of one step are read
together at its next pass (right-aligned, padded and masked to the longest row). The rows' first masks,
the costliest, are computed on a worker thread while the prompts are read (llguidance drops the GIL).

`steps` is the same loop as a generator that yields after queuing each pass: on a GPU, `lanes.run`
decodes two half-batches in turn with it, one lane's grammar work overlapping the other's pass.
"""

from __future__ import annotations

import os
import time
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, field

import torch
from transformers import DynamicCache
from transformers.cache_utils import DynamicLayer

from . import batch_pass, lanes, one_row
from .constrained import unpack_bits
from .kv_buffer import BufferLayer, PackedRow, as_layers, cache_of

_POOL: list = []
os.register_at_fork(after_in_child=_POOL.clear)  # a forked worker has no threads: it starts its own pool


def _pool() -> ThreadPoolExecutor:
    if not _POOL:
        _POOL.append(ThreadPoolExecutor(1, thread_name_prefix="adapt-mask"))
    return _POOL[0]


SHARED_MIN = 64  # a new session starts from another's cache when they share at least this many tokens


@dataclass
class Row:
    """One generation: prompt token ids, token limit, stop strings and an optional session key (rows
    of the same session in one batch share nothing: the last one's cache is kept)."""

    prompt: list
    max_tokens: int
    stop: tuple = ()
    session: str | None = None
    tokens: list = field(default_factory=list)
    reused: int = 0  # prompt tokens read from the session's cache
    forced: int = 0  # generated tokens the grammar forced (taken without a forward pass of their own)


class Sessions:
    """Per-session key/value caches: (token ids, per-layer (keys, values) of shape [1, heads, T, dim]).
    Least recently used first out beyond `limit` sessions; `limit` 0 keeps none."""

    def __init__(self, limit: int = 32):
        self.limit = limit
        self._items: OrderedDict = OrderedDict()

    def __len__(self) -> int:
        return len(self._items)

    def take(self, key: str | None):
        """Remove and return a session's (tokens, layers), or None."""
        return self._items.pop(key, None) if key is not None else None

    def put(self, key: str | None, tokens: list, layers: list) -> None:
        """Store a session's cache (most recently used)."""
        if key is None or self.limit <= 0:
            return
        self._items[key] = (tokens, layers)
        self._items.move_to_end(key)
        while len(self._items) > self.limit:
            self._items.popitem(last=False)

    def drop(self, key: str) -> None:
        """Forget a session."""
        self._items.pop(key, None)

    def shared(self, tokens: list, least: int = SHARED_MIN):
        """The (tokens, layers) of the kept session sharing the longest prefix with `tokens` (at least
        `least` tokens), left in place: a new episode's first prompt repeats the system message every
        episode of its agent opens with (the action list and the house: ~1,500 of SmolLM2's tokens),
        so it reads only what follows. The layers are read, never written (caches are copied into a
        batch before a pass extends them)."""
        best, hit = least - 1, None
        for item in self._items.values():
            n = common_prefix(item[0], tokens)
            if n > best:
                best, hit = n, item
        return hit


def common_prefix(a: list, b: list) -> int:
    """Length of the longest common prefix of two token lists (compared a slice at a time: a session's
    tokens are most often a whole prefix of the next prompt, found by one comparison)."""
    n = min(len(a), len(b))
    if a[:n] == b[:n]:
        return n
    lo, hi = 0, n  # a[:lo] == b[:lo] and a[:hi] != b[:hi]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if a[lo:mid] == b[lo:mid]:
            lo = mid
        else:
            hi = mid
    return lo


GQA_FLAG = "TRANSFORMERS_SDPA_FORCE_GQA"


@contextmanager
def grouped_heads(model):
    """For a pass over several new tokens with a mask on the CPU: let torch's SDPA handle grouped
    key/value heads (`enable_gqa`) instead of transformers repeating them, which copies every layer's
    whole cache (measured, 16 rows with 2 new tokens each: 7.3 ms a pass with the copy, 4.9 ms
    without). transformers reads the switch at each call; the logits are the same (tested). On a GPU,
    SDPA with a mask and `enable_gqa` falls back to its slow kernel, so there it stays off."""
    if model.device.type != "cpu" or os.environ.get(GQA_FLAG) is not None:
        yield
        return
    os.environ[GQA_FLAG] = "1"
    try:
        yield
    finally:
        os.environ.pop(GQA_FLAG, None)


_CACHE_ARG: dict = {}  # model class -> the name its forward takes the key/value cache by


def cache_arg(model, cache) -> dict:
    """The keyword that hands `cache` to the model's forward: `cache` where the model takes it (transformers
    5.2x renamed it and warns, FutureWarning, on every call that still says `past_key_values`), else
    `past_key_values`."""
    kind = type(model)
    if kind not in _CACHE_ARG:
        import inspect

        params = inspect.signature(model.forward).parameters
        _CACHE_ARG[kind] = "cache" if "cache" in params else "past_key_values"
    return {_CACHE_ARG[kind]: cache}


def _n_layers(model) -> int:
    return len(DynamicCache(config=model.config).layers)


SHORT = 256  # rows with a cache and at most this many new tokens read them in one batched pass


def reuse(row: Row, sessions: Sessions) -> list | None:
    """Take the row's session cache (its own `BufferLayer`s, cut to the prefix it shares with the row's
    prompt and written on in place) or, for a session without one, a copy of the kept cache sharing the
    longest prefix (`Sessions.shared`); at least the prompt's last token is left to read, for the first
    new token's logits. Sets `row.reused`."""
    hit = sessions.take(row.session)
    row.reused = 0
    if hit is not None:
        return _start_from(row, hit, own=True)
    return _start_from(row, sessions.shared(row.prompt))


def _start_from(row: Row, hit, own: bool = False) -> list | None:
    if hit is None:
        return None
    tokens, cached = hit
    start = min(common_prefix(tokens, row.prompt), len(row.prompt) - 1)
    if start <= 0:
        return None
    row.reused = start
    if isinstance(cached, PackedRow):  # kept from a pooled decode (`batch_pass`)
        if own:
            cached.truncate(start)
            return cached
        return cached.head(start)
    if own:
        for layer in cached:
            layer.truncate(start)
        return list(cached)
    room = len(row.prompt) - start + row.max_tokens  # what the row reads and decodes next: no second copy
    return [BufferLayer(layer.keys[:, :, :start], layer.values[:, :, :start], room) for layer in cached]


def prefill(model, row: Row, layers: list | None, room: int = 0):
    """Read the row's prompt after its `row.reused` cached tokens into `layers` (`BufferLayer`s; None:
    new ones), leaving `room` positions to decode into; returns (last logits [V], layers)."""
    start = row.reused
    layers = as_layers(layers)
    ids = torch.tensor([row.prompt[start:]], dtype=torch.long, device=model.device)
    pos = torch.arange(start, len(row.prompt), device=model.device).unsqueeze(0)
    if layers is None:
        layers = [BufferLayer(room=room) for _ in range(_n_layers(model))]
    else:
        for layer in layers:
            layer.reserve(len(row.prompt) + room)
    cache = cache_of(layers, model.config)
    with grouped_heads(model):
        out = model(input_ids=ids, position_ids=pos, use_cache=True, logits_to_keep=1, **cache_arg(model, cache))
    return out.logits[0, -1].float(), layers


def prefill_many(model, rows: list, layers: list, pad_id: int = 0, room: int = 0, graphs=None) -> tuple:
    """Read several cached rows' new tokens in one forward pass: caches left-padded to one width,
    new tokens right-aligned after them (padding between, masked), each at its own positions, with
    `room` positions after them (in `graphs`' pool where given). Returns ([last logits [V] per row],
    batch cache, attention mask [B, W])."""
    cached = [r.reused for r in rows]
    width, most = max(cached), max(len(r.prompt) - r.reused for r in rows)
    cache, mask = _stack(model, layers, cached, most + room, graphs)
    ids, pos, tail = batch_pass.right_aligned([r.prompt[r.reused:] for r in rows], cached, pad_id)
    dev = model.device
    mask = torch.cat([mask, tail.to(mask.device)], dim=1)
    if batch_pass.mode(model) != "hf":
        bias = batch_pass.attention_bias(mask, most, model.dtype)
        logits = _head(model, batch_pass.forward(model, cache.layers, ids.to(dev), pos.to(dev), bias), None)
        return [logits[i] for i in range(len(rows))], cache, mask
    with grouped_heads(model):
        out = model(input_ids=ids.to(dev), attention_mask=mask, position_ids=pos.to(dev), use_cache=True,
                    **cache_arg(model, cache), cache_position=torch.arange(width, width + most, device=dev),
                    logits_to_keep=1)
    logits = out.logits[:, -1].float()
    return [logits[i] for i in range(len(rows))], cache, mask


def _shared_prefixes(rows: list, layers: list) -> dict:
    """{row index: length} for the rows without a cache whose prompts share at least SHARED_MIN tokens
    with another such row: each group's longest common prefix (an agent's system message, the same
    in every episode)."""
    new = sorted((i for i, cached in enumerate(layers) if cached is None), key=lambda i: rows[i].prompt)
    out: dict = {}
    if len(new) < 2:
        return out
    group: list = []
    shared = 0
    for a, b in zip(new, new[1:] + [None], strict=True):
        n = common_prefix(rows[a].prompt, rows[b].prompt) if b is not None else 0
        if n >= SHARED_MIN:
            group.append(a)
            shared = n if len(group) == 1 else min(shared, n)
            continue
        if group:
            out.update({i: shared for i in (*group, a)})
        group = []
    return out


def _read_shared(model, rows: list, layers: list) -> None:
    """Read each group's shared prefix once (`_shared_prefixes`) and start its rows from a copy of it."""
    groups: dict = {}
    for i, n in _shared_prefixes(rows, layers).items():
        groups.setdefault((n, tuple(rows[i].prompt[:n])), []).append(i)
    for (_, prefix), members in groups.items():
        _, prefix_layers = prefill(model, Row(list(prefix), 0), None)
        for i in members:
            layers[i] = _start_from(rows[i], (list(prefix), prefix_layers))


def prefill_rows(model, rows: list, sessions: Sessions, pad_id: int = 0, together: bool = True,
                 room: int = 0, graphs=None) -> tuple:
    """(last logits, layers) per row, and the batch cache and mask when every row was read in one
    pass (None otherwise). Rows without a cache that open with the same prefix (≥ SHARED_MIN tokens)
    start from it, read once. With `together`, rows with a cache and a short new part are read in one
    pass (`prefill_many`), the others one by one. On a GPU one pass saves a forward pass per row; on a
    CPU reading is compute-bound and the padded pass gains little or loses (measured in 16-episode
    rollouts: +13% on the tiny model, -15% on a 4-layer one), so the backend turns it off there.
    `room`: positions each row's own layers keep free to decode into; `graphs`: the pool to read into
    (`batch_pass.DecodeGraphs`)."""
    layers = [reuse(r, sessions) for r in rows]
    _read_shared(model, rows, layers)
    short = [i for i, r in enumerate(rows)
             if together and layers[i] is not None and len(r.prompt) - r.reused <= SHORT]
    out: list = [None] * len(rows)
    if len(short) > 1:
        logits, cache, mask = prefill_many(model, [rows[i] for i in short], [layers[i] for i in short], pad_id,
                                           room, graphs if len(short) == len(rows) else None)
        if len(short) == len(rows):
            return list(zip(logits, [None] * len(rows), strict=True)), (cache, mask)
        width = max(rows[i].reused for i in short)
        for k, i in enumerate(short):
            new = len(rows[i].prompt) - rows[i].reused
            out[i] = (logits[k], [layer.row_parts(k, rows[i].reused, width, new) for layer in cache.layers])
    for i, r in enumerate(rows):
        if out[i] is None:
            out[i] = prefill(model, r, layers[i], room if len(rows) == 1 else 0)
    return out, None


def _stack(model, rows_layers: list, lengths: list, room: int, graphs=None) -> tuple:
    """One cache holding the rows' caches left-padded to one width, with `room` positions to grow (in
    `graphs`' pool where it fits); returns (cache, attention mask [B, W])."""
    width = max(lengths)
    if graphs is not None and graphs.fits(len(rows_layers), width + room):
        layers, mask = graphs.stack(rows_layers, lengths)
        return cache_of(layers, model.config), mask
    rows_layers = [as_layers(x) for x in rows_layers]
    layers = []
    for li in range(len(rows_layers[0])):
        k0 = rows_layers[0][li].keys
        shape = (len(rows_layers), k0.shape[1], width, k0.shape[3])
        ks, vs = k0.new_zeros(shape), k0.new_zeros(shape)
        for r, row in enumerate(rows_layers):
            k, v = row[li].keys, row[li].values
            ks[r, :, width - k.shape[2]:] = k[0]
            vs[r, :, width - v.shape[2]:] = v[0]
        layers.append(BufferLayer(ks, vs, room))
    mask = torch.zeros((len(lengths), width), dtype=torch.long, device=k0.device)
    for r, n in enumerate(lengths):
        mask[r, width - n:] = 1
    return cache_of(layers, model.config), mask


def decode(model, rows: list, sessions: Sessions, picker, stopped, pad_id: int = 0, together: bool = True) -> float:
    """Generate every row's tokens in place (`row.tokens`); `steps` with nothing else to run between its
    passes. Returns the seconds spent reading the prompts (the rest is decoding)."""
    return lanes.run([steps(model, rows, sessions, picker, stopped, pad_id, together)])[0]


def steps(model, rows: list, sessions: Sessions, picker, stopped, pad_id: int = 0, together: bool = True,
          lane: int = 0):
    """The decoding of `rows` as a generator: it yields each time it has queued a pass and the pick of
    the tokens that pass makes (on a GPU both run while the caller does other work: `lanes.run` decodes
    another lane's rows there), and returns the seconds spent reading the prompts.

    Rows' tokens are generated in place (`row.tokens`). `picker.pick(logits [B, V], active row
    indices, steps) -> token ids [B]` masks and picks the next token of each active row (the grammar
    acts there) and `picker.advance(rows, tokens) -> {row: token}` hears which tokens those rows took
    and names the rows whose grammar now allows a single token, which they take without a forward pass
    of their own (a row's tokens of one step are read together at the next); `stopped(row_index, row)
    -> bool` says a row is over after its newest token (EOS, stop string, limit). Sessions get their
    rows' caches back. `together`: see `prefill_rows`. `lane`: which of the model's key/value pools
    the rows decode in (`batch_pass.graphs_of`; lanes decoded in turn need one each).

    The cache: a single row decodes into its own layers (the session's buffer, written in place: no
    copy per step) with no attention mask; several rows share one left-padded batch buffer, with a
    mask only while their lengths differ. In a large batch cache (`COMPACT_BYTES`) a row that stops
    stays (reading a pad token, its logits unused) until half the rows have stopped: then the running
    rows' caches are copied once into a smaller buffer, instead of once per stopping row."""
    t0 = time.perf_counter()
    picker.start(list(range(len(rows))))  # the first masks need no prompt: computed while the prompts are read
    room = max(r.max_tokens for r in rows)
    graphs = batch_pass.graphs_of(model, len(rows), max(len(r.prompt) for r in rows) + 2 * room, lane)
    read_rows, batch = prefill_rows(model, rows, sessions, pad_id, together, room, graphs)
    first, layers = zip(*read_rows, strict=True)
    reading = time.perf_counter() - t0
    read = [len(r.prompt) for r in rows]  # each row's tokens in the cache
    cache, mask = batch if batch is not None else _batch_cache(model, list(layers), read, room, graphs)
    if graphs is not None and not graphs.holds(cache.layers):
        cache.layers = graphs.adopt(cache.layers)
    narrow = narrow_head(model)
    slots = list(range(len(rows)))  # the request row in each cache row (None: a stopped row riding along)
    active = list(slots)
    picked = Picked(picker.pick(torch.stack(first), active, {i: len(rows[i].tokens) for i in active}))
    yield
    while active:
        for i, token in zip(active, picked.tolist(), strict=True):
            rows[i].tokens.append(token)
        running = _take_forced(rows, [i for i in active if not stopped(i, rows[i])], picker, stopped)
        if len(running) < len(active):
            _store(rows, slots, running, read, cache, mask, sessions, graphs)
            if not running:
                break
            slots = [i if i in running else None for i in slots]
            if 2 * len(running) <= len(slots) or _nbytes(cache) < COMPACT_BYTES:
                cache, mask, slots = _compact(cache, mask, slots)
            active = [i for i in slots if i is not None]
        new = [rows[i].tokens[read[i] - len(rows[i].prompt):] if i is not None else [pad_id] for i in slots]
        at = [read[i] if i is not None else 0 for i in slots]
        out, mask = _forward(model, cache, mask, new, at, pad_id, picker.allowed(active) if narrow else None, graphs)
        logits = out if len(active) == len(slots) else out[[k for k, i in enumerate(slots) if i is not None]]
        for i, t in zip(slots, new, strict=True):
            if i is not None:
                read[i] += len(t)
        picked = Picked(picker.pick(logits, active, {i: len(rows[i].tokens) for i in active}))
        yield
    return reading


class Picked:
    """A pass's picked tokens on their way to the host: on CUDA copied into pinned memory without
    waiting, with an event after the copy, so that reading them waits for this pass's work only (not
    for another lane's pass queued after it); elsewhere, the tokens themselves."""

    def __init__(self, tokens: torch.Tensor):
        self.tokens, self.done = tokens, None
        if tokens.is_cuda:
            self.tokens = torch.empty(tokens.shape, dtype=tokens.dtype, pin_memory=True)
            self.tokens.copy_(tokens, non_blocking=True)
            self.done = torch.cuda.Event()
            self.done.record()

    def tolist(self) -> list:
        """The token ids (waits for their copy)."""
        if self.done is not None:
            self.done.synchronize()
        return self.tokens.tolist()


def _batch_cache(model, layers: list, read: list, room: int, graphs=None) -> tuple:
    """(cache, attention mask or None) to decode the rows in: a single row's own layers, else the rows'
    caches left-padded into one buffer (`graphs`' pool where given); no mask where no row is padded
    (attention without an explicit mask: the fast kernels)."""
    if len(layers) == 1 and graphs is None:
        return cache_of(as_layers(layers[0]), model.config), None
    cache, mask = _stack(model, layers, read, room, graphs)
    return cache, None if len(set(read)) == 1 else mask


COMPACT_BYTES = 64 * 2**20  # a batch cache smaller than this is compacted as soon as a row stops (copying it
# costs less than passes over stopped rows: the tiny model's 64 rows measured 20% more CPU a step riding)


def _nbytes(cache) -> int:
    """Bytes of a batch cache's key and value buffers."""
    k = cache.layers[0]._k
    return 2 * k.numel() * k.element_size() * len(cache.layers)


def _compact(cache, mask, slots: list) -> tuple:
    """Keep only the running rows in the batch cache (one copy of their caches)."""
    keep = [k for k, i in enumerate(slots) if i is not None]
    idx = torch.tensor(keep, dtype=torch.long, device=cache.layers[0].keys.device)
    for layer in cache.layers:
        layer.select(idx)
    return cache, None if mask is None else mask[idx.to(mask.device)], [slots[k] for k in keep]


def _take_forced(rows: list, running: list, picker, stopped) -> set:
    """Feed the running rows' newest tokens to the picker and append the tokens their grammars force,
    as long as some row has one; returns the rows still running."""
    running = set(running)
    chain = sorted(running)
    while chain:
        forced = picker.advance(chain, [rows[i].tokens[-1] for i in chain])
        chain = []
        for i, token in forced.items():
            rows[i].tokens.append(token)
            rows[i].forced += 1
            if stopped(i, rows[i]):
                running.discard(i)
            else:
                chain.append(i)
    return running


def _store(rows: list, slots: list, running: set, read: list, cache, mask, sessions: Sessions,
           graphs=None) -> None:
    """Give the sessions of the rows that just stopped their caches (the tokens read so far): the
    cache itself for a single row with no padding, else a copy of the row's real positions (from a
    `graphs` pool: one `PackedRow` copy for all layers)."""
    if sessions.limit <= 0:
        return
    if graphs is not None and graphs.holds(cache.layers):
        host = None if mask is None else mask.cpu()  # one transfer for every row's positions
        for k, i in enumerate(slots):
            if i is not None and i not in running and rows[i].session is not None:
                where = None if host is None else host[k].nonzero().view(-1)
                sessions.put(rows[i].session, (rows[i].prompt + rows[i].tokens)[:read[i]],
                             graphs.packed(k, where, cache.get_seq_length()))
        return
    for k, i in enumerate(slots):
        if i is None or i in running or rows[i].session is None:
            continue
        where = None if mask is None else mask[k].nonzero().view(-1)
        sessions.put(rows[i].session, (rows[i].prompt + rows[i].tokens)[:read[i]],
                     [layer.row(k, where) for layer in cache.layers])


HEAD_TYPES = ("llama", "mistral", "qwen2", "qwen3")  # causal LMs whose logits are the plain output layer's
NARROW = 4  # a pass computes only the allowed tokens' logits when they are at most 1/NARROW of the vocabulary
HEAD_MIN = 2**23  # ... and the output layer has at least this many weights (SmolLM2's: 28M; the tiny model's: 0.2M)


def narrow_head(model) -> bool:
    """Whether a pass may compute only the grammar's allowed tokens' logits: on the CPU (where the output
    layer is a fifth of a small model's weights read per token: SmolLM2's 49,152 x 576), for model types
    whose logits are the output layer's alone (no scaling or soft-capping), with a bias-free layer large
    enough to matter (`HEAD_MIN` weights)."""
    head = model.get_output_embeddings()
    return (model.device.type == "cpu" and getattr(model.config, "model_type", None) in HEAD_TYPES
            and hasattr(model, "model") and isinstance(head, torch.nn.Linear) and head.bias is None
            and head.weight.numel() >= HEAD_MIN)


def _logits(model, head, **kwargs) -> torch.Tensor:
    """The last position's logits [B, V] (float32); with `head` (sorted token ids) only those tokens'
    are computed, the others -inf (the grammar forbids them: the same logits where allowed)."""
    cache = kwargs.pop("cache")
    if head is None:
        return model(**kwargs, **cache_arg(model, cache), logits_to_keep=1).logits[:, -1].float()
    return _head(model, model.model(**kwargs, **cache_arg(model.model, cache)).last_hidden_state[:, -1], head)


def _head(model, h: torch.Tensor, head) -> torch.Tensor:
    """Logits [B, V] (float32) of last hidden states [B, hidden]: every token's (`head` None) or only
    `head`'s, the others -inf."""
    w = model.get_output_embeddings().weight
    if head is None:
        return model.get_output_embeddings()(h).float()
    out = torch.full((h.shape[0], w.shape[0]), float("-inf"), dtype=torch.float32, device=h.device)
    out[:, head] = torch.nn.functional.linear(h, w[head]).float()
    return out


def lean(model) -> bool:
    """Whether one unmasked row's passes go through `one_row.step` (on the CPU, where a pass's fixed
    costs weigh: a Llama model, `one_row.supported`); decided once per model."""
    hit = model.__dict__.get("_adapt_lean")
    if hit is None:
        hit = model.__dict__["_adapt_lean"] = model.device.type == "cpu" and one_row.supported(model)
    return hit


def _forward(model, cache, mask, new: list, read: list, pad_id: int, head=None, graphs=None) -> tuple:
    """One decoding pass: each row reads its new tokens (most often one; more when its grammar forced
    some) at its own positions, right-aligned and padded (masked) to the longest. `mask` None: no
    padding so far (it is made when rows read different numbers of tokens). `head`: the token ids whose
    logits are needed (None: all; `_logits`). `graphs`: the model's `batch_pass.DecodeGraphs`, which
    take one-token passes over the pool the cache lives in. Returns (logits [B, V], mask)."""
    width, most = cache.get_seq_length(), max(len(t) for t in new)
    dev = model.device
    if mask is None and len(new) == 1 and most == 1 and lean(model):  # one row, one token: the lean pass
        return _head(model, one_row.step(model, cache, new[0][0], read[0]), head), None
    if graphs is not None and graphs.takes(cache.layers, most):
        return graphs.step(cache.layers, new, read, mask)
    if mask is None and any(len(t) != most for t in new):
        mask = torch.ones((len(new), width), dtype=torch.long, device=cache.layers[0].keys.device)
    if most == 1:
        ids = torch.tensor(new, dtype=torch.long, device=dev)
        pos = torch.tensor(read, dtype=torch.long, device=dev).view(-1, 1)
        if mask is not None:
            mask = torch.cat([mask, mask.new_ones((mask.shape[0], 1))], dim=1)
    else:
        ids, pos, tail = batch_pass.right_aligned(new, read, pad_id)
        ids, pos = ids.to(dev), pos.to(dev)
        if mask is not None:
            mask = torch.cat([mask, tail.to(mask.device)], dim=1)
    if batch_pass.mode(model) != "hf":
        bias = None if mask is None else batch_pass.attention_bias(mask, most, model.dtype)
        return _head(model, batch_pass.forward(model, cache.layers, ids, pos, bias), head), mask
    with grouped_heads(model) if most > 1 else nullcontext():
        logits = _logits(model, head, input_ids=ids, attention_mask=mask, position_ids=pos, use_cache=True,
                         cache=cache, cache_position=torch.arange(width, width + most, device=dev))
    return logits, mask


def loop_supported(model) -> bool:
    """Whether this loop handles the model's cache (plain dynamic layers: no sliding windows, no
    recurrent state); other models go through `model.generate`."""
    try:
        cache = DynamicCache(config=model.config)
    except Exception:  # noqa: BLE001 - any model whose cache we cannot build takes the generic path
        return False
    return bool(cache.layers) and all(type(layer) is DynamicLayer for layer in cache.layers)


def _or_rows(words: torch.Tensor) -> torch.Tensor:
    """Bitwise or of the rows of an int32 tensor [n, W]."""
    out = words[0].clone()
    for row in words[1:]:
        out |= row
    return out


class Picker:
    """Masks and samples each step's tokens: greedy at temperature 0, else each row from its softmax at its
    temperature with its own generator (`sampling.RowSampler`). With a grammar processor, the rows' first masks (the costliest: the
    start of an action allows many tokens) are computed on a worker thread while the prompts are read;
    later ones as the rows take their tokens (`advance`), which also finds the tokens a grammar forces.
    (Computing masks on the worker during each forward pass instead measured slower on the CPU: 0.82–0.89
    of unconstrained speed against 1.03–1.32 fast-forwarding, and on a GPU forward passes are the cost.)"""

    def __init__(self, proc, sampler=None):
        self.proc, self.sampler = proc, sampler  # sampler: `sampling.RowSampler` (None: greedy)
        self._first = None

    def pick(self, logits: torch.Tensor, active: list, steps) -> torch.Tensor:
        """The next token of each active row (`logits` row k is request row `active[k]`; `steps`: each
        row's index of the token being chosen, for steering rows near their limit to close)."""
        if self.proc is not None:
            if self._first is not None:
                live, self._first = self._first.result(), None
            else:
                live = self.proc.live(active)
            t0 = time.perf_counter()
            self.proc.mask(logits, active, live, steps)
            self.proc.mask_seconds += time.perf_counter() - t0
        if self.sampler is not None:
            return self.sampler.pick(logits, active)
        return logits.argmax(dim=-1)

    def allowed(self, active: list) -> torch.Tensor | None:
        """The token ids any of the active rows' next masks allows (sorted), when every active row is
        constrained and they are at most 1/NARROW of the vocabulary; else None (all logits needed)."""
        if self.proc is None or not active or len(self.proc.live(active)) != len(active):
            return None
        words = self.proc.bitmask[torch.tensor(active, dtype=torch.long)]
        union = _or_rows(words)
        ids = unpack_bits(union.unsqueeze(0), self.proc.vocab)[0].nonzero().view(-1)
        return ids if 0 < len(ids) <= self.proc.vocab // NARROW else None

    def start(self, rows: list) -> None:
        """Start computing the rows' first masks (on the worker thread: the prompts are read meanwhile)."""
        if self.proc is not None:
            self._first = _pool().submit(self._timed, self.proc.fill, rows)

    def advance(self, rows: list, tokens: list) -> dict:
        """These rows took these tokens: feed them and compute the rows' next masks; returns {row:
        token} for the rows whose grammar now allows a single token."""
        if self.proc is None:
            return {}
        return self._timed(self._advance, rows, tokens)

    def _advance(self, rows: list, tokens: list) -> dict:
        self.proc.feed(rows, tokens)
        return self.proc.forced(self.proc.fill(rows))

    def _timed(self, fn, *args):
        t0 = time.perf_counter()
        try:
            return fn(*args)
        finally:
            self.proc.mask_seconds += time.perf_counter() - t0
