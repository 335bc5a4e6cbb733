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
    """Length of the longest common prefix of two token lists."""
    n = min(len(a), len(b))
    i = 0
    while i < n and a[i] == b[i]:
        i += 1
    return i


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


def _layers(cache: DynamicCache) -> list:
    return [(layer.keys, layer.values) for layer in cache.layers]


def _cache(layers: list, config) -> DynamicCache:
    return DynamicCache(ddp_cache_data=layers, config=config)


SHORT = 256  # rows with a cache and at most this many new tokens read them in one batched pass


def reuse(row: Row, sessions: Sessions) -> list | None:
    """Take the row's session cache (or, for a session without one, the kept cache sharing the longest
    prefix, `Sessions.shared`) and keep the prefix it shares with the row's prompt (at least the
    prompt's last token is left to read, for the first new token's logits); sets `row.reused`."""
    hit = sessions.take(row.session)
    row.reused = 0
    return _start_from(row, hit if hit is not None else sessions.shared(row.prompt))


def _start_from(row: Row, hit) -> list | None:
    if hit is None:
        return None
    tokens, cached = hit
    start = min(common_prefix(tokens, row.prompt), len(row.prompt) - 1)
    if start <= 0:
        return None
    row.reused = start
    return [(k[:, :, :start], v[:, :, :start]) for k, v in cached]


def _donor(row: Row, donors: list):
    """The (tokens, layers) read earlier in this call sharing the longest prefix with the row's prompt."""
    best = max(donors, key=lambda d: common_prefix(d[0], row.prompt), default=None)
    return best if best is not None and common_prefix(best[0], row.prompt) >= SHARED_MIN else None


def prefill(model, row: Row, layers: list | None):
    """Read the row's prompt after its `row.reused` cached tokens; returns (last logits [V], layers)."""
    start = row.reused
    ids = torch.tensor([row.prompt[start:]], dtype=torch.long, device=model.device)
    pos = torch.arange(start, len(row.prompt), device=model.device).unsqueeze(0)
    cache = _cache(layers, model.config) if layers else DynamicCache(config=model.config)
    with grouped_heads(model):
        out = model(input_ids=ids, position_ids=pos, use_cache=True, logits_to_keep=1, **cache_arg(model, cache))
    return out.logits[0, -1].float(), _layers(cache)


def prefill_many(model, rows: list, layers: list, pad_id: int = 0) -> list:
    """Read several cached rows' new tokens in one forward pass: caches left-padded to one width,
    new tokens right-aligned after them (padding between, masked), each at its own positions. Returns
    (last logits [V], layers) per row."""
    cached = [r.reused for r in rows]
    new = [len(r.prompt) - r.reused for r in rows]
    width, room = max(cached), max(new)
    cache, mask = _stack(model, layers, cached, room)
    ids, pos, tail = _right_aligned([r.prompt[r.reused:] for r in rows], cached, pad_id)
    dev = model.device
    with grouped_heads(model):
        out = model(input_ids=ids.to(dev), attention_mask=torch.cat([mask, tail.to(mask.device)], dim=1),
                    position_ids=pos.to(dev), use_cache=True, **cache_arg(model, cache),
                    cache_position=torch.arange(width, width + room, device=dev), logits_to_keep=1)
    logits = out.logits[:, -1].float()
    return [(logits[i], [layer.row_parts(i, cached[i], width, new[i]) for layer in cache.layers])
            for i in range(len(rows))]


def prefill_rows(model, rows: list, sessions: Sessions, pad_id: int = 0, together: bool = True) -> list:
    """(last logits, layers) per row: with `together`, rows with a cache and a short new part in one
    pass (`prefill_many`), the others (a first step: the whole prompt) one by one. On a GPU one pass
    saves a forward pass per row; on a CPU reading is compute-bound and the padded pass gains little or
    loses (measured in 16-episode rollouts: +13% on the tiny model, -15% on a 4-layer one), so the
    backend turns it off there."""
    layers = [reuse(r, sessions) for r in rows]
    short = [i for i, r in enumerate(rows)
             if together and layers[i] is not None and len(r.prompt) - r.reused <= SHORT]
    out: list = [None] * len(rows)
    if len(short) > 1:
        for i, res in zip(short, prefill_many(model, [rows[i] for i in short], [layers[i] for i in short], pad_id),
                          strict=True):
            out[i] = res
    donors: list = []  # prompts read whole in this call: a later new episode starts from the one it shares most with
    for i, r in enumerate(rows):
        if out[i] is None:
            if layers[i] is None and donors:
                layers[i] = _start_from(r, _donor(r, donors))
            out[i] = prefill(model, r, layers[i])
            if r.reused == 0:
                donors.append((r.prompt, out[i][1]))
    return out


class BufferLayer(DynamicLayer):
    """A cache layer whose keys and values live in a buffer with room to grow: a decoding step writes
    its position in place instead of concatenating (copying) the whole cache, as `DynamicLayer` does."""

    def __init__(self, keys: torch.Tensor, values: torch.Tensor, room: int):
        super().__init__()
        b, h, n, d = keys.shape
        self._k, self._v = keys.new_empty((b, h, n + room, d)), values.new_empty((b, h, n + room, d))
        self._k[:, :, :n], self._v[:, :, :n] = keys, values
        self.n = n
        self.dtype, self.device, self.is_initialized = keys.dtype, keys.device, True
        self._views()

    def _views(self) -> None:
        self.keys, self.values = self._k[:, :, :self.n], self._v[:, :, :self.n]

    def update(self, key_states: torch.Tensor, value_states: torch.Tensor, *args, **kwargs) -> tuple:
        """Write the new positions after the cached ones; returns the cache so far."""
        q = key_states.shape[-2]
        if self.n + q > self._k.shape[2]:
            more = max(q, self._k.shape[2])
            self._k = torch.cat([self._k, self._k.new_empty((*self._k.shape[:2], more, self._k.shape[3]))], dim=2)
            self._v = torch.cat([self._v, self._v.new_empty((*self._v.shape[:2], more, self._v.shape[3]))], dim=2)
        self._k[:, :, self.n:self.n + q], self._v[:, :, self.n:self.n + q] = key_states, value_states
        self.n += q
        self._views()
        return self.keys, self.values

    def get_seq_length(self) -> int:
        """Positions cached."""
        return self.n

    def select(self, rows: torch.Tensor) -> None:
        """Keep only these batch rows."""
        self._k, self._v = self._k[rows], self._v[rows]
        self._views()

    def row_parts(self, k: int, cached: int, width: int, new: int) -> tuple:
        """Row k after a batched prefill: its `cached` positions before `width` and its `new` last ones."""
        keys = torch.cat([self.keys[k:k + 1, :, width - cached:width], self.keys[k:k + 1, :, self.n - new:]], dim=2)
        values = torch.cat([self.values[k:k + 1, :, width - cached:width], self.values[k:k + 1, :, self.n - new:]],
                           dim=2)
        return keys, values

    def row(self, k: int, where: torch.Tensor) -> tuple:
        """Row k's cached positions `where` (its real ones, padding left out), as a batch of one (a copy)."""
        where = where.to(self.keys.device)
        return self.keys[k:k + 1, :, where], self.values[k:k + 1, :, where]


def _stack(model, rows_layers: list, lengths: list, room: int) -> tuple:
    """One cache holding the rows' caches left-padded to one width, with `room` positions to grow;
    returns (cache, attention mask [B, W])."""
    width = max(lengths)
    layers = []
    for li in range(len(rows_layers[0])):
        k0 = rows_layers[0][li][0]
        shape = (len(rows_layers), k0.shape[1], width, k0.shape[3])
        ks, vs = k0.new_zeros(shape), k0.new_zeros(shape)
        for r, row in enumerate(rows_layers):
            k, v = row[li]
            ks[r, :, width - k.shape[2]:] = k[0]
            vs[r, :, width - v.shape[2]:] = v[0]
        layers.append(BufferLayer(ks, vs, room))
    cache = DynamicCache(config=model.config)
    cache.layers = layers
    mask = torch.zeros((len(lengths), width), dtype=torch.long, device=k0.device)
    for r, n in enumerate(lengths):
        mask[r, width - n:] = 1
    return cache, mask


def decode(model, rows: list, sessions: Sessions, picker, stopped, pad_id: int = 0, together: bool = True) -> float:
    """Generate every row's tokens in place (`row.tokens`). `picker.pick(logits [B, V], active row
    indices, steps) -> token ids [B]` masks and picks the next token of each active row (the grammar
    acts there) and `picker.advance(rows, tokens) -> {row: token}` hears which tokens those rows took
    and names the rows whose grammar now allows a single token, which they take without a forward pass
    of their own (a row's tokens of one step are read together at the next); `stopped(row_index, row)
    -> bool` says a row is over after its newest token (EOS, stop string, limit). Sessions get their
    rows' caches back. `together`: see `prefill_rows`. Returns the seconds spent reading the prompts
    (the rest is decoding)."""
    t0 = time.perf_counter()
    picker.start(list(range(len(rows))))  # the first masks need no prompt: computed while the prompts are read
    first, layers = zip(*prefill_rows(model, rows, sessions, pad_id, together), strict=True)
    reading = time.perf_counter() - t0
    read = [len(r.prompt) for r in rows]  # each row's tokens in the cache
    active = list(range(len(rows)))
    logits = torch.stack(first)
    cache, mask = _stack(model, list(layers), read, max(r.max_tokens for r in rows))
    while active:
        picked = picker.pick(logits, active, {i: len(rows[i].tokens) for i in active}).tolist()
        for k, i in enumerate(active):
            rows[i].tokens.append(picked[k])
        running = _take_forced(rows, [i for i in active if not stopped(i, rows[i])], picker, stopped)
        if len(running) < len(active):
            _store(rows, active, running, read, cache, mask, sessions)
            if not running:
                break
            keep = torch.tensor([k for k, i in enumerate(active) if i in running], dtype=torch.long,
                                device=mask.device)
            for layer in cache.layers:
                layer.select(keep)
            mask, active = mask[keep], [i for i in active if i in running]
        new = [rows[i].tokens[read[i] - len(rows[i].prompt):] for i in active]
        logits, mask = _forward(model, cache, mask, new, [read[i] for i in active], pad_id)
        for i, t in zip(active, new, strict=True):
            read[i] += len(t)
    return reading


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


def _store(rows: list, active: list, running: set, read: list, cache, mask: torch.Tensor, sessions: Sessions) -> None:
    """Give the sessions of the rows that stopped their caches (the tokens read so far)."""
    if sessions.limit <= 0:
        return
    for k, i in enumerate(active):
        if i in running or rows[i].session is None:
            continue
        where = mask[k].nonzero().view(-1)
        sessions.put(rows[i].session, (rows[i].prompt + rows[i].tokens)[:read[i]],
                     [layer.row(k, where) for layer in cache.layers])


def _forward(model, cache, mask: torch.Tensor, new: list, read: list, pad_id: int) -> tuple:
    """One decoding pass: each active row reads its new tokens (most often one; more when its grammar
    forced some) at its own positions, right-aligned and padded (masked) to the longest."""
    width, most = cache.get_seq_length(), max(len(t) for t in new)
    dev = model.device
    if most == 1:
        ids = torch.tensor(new, dtype=torch.long, device=dev)
        pos = torch.tensor(read, dtype=torch.long, device=dev).view(-1, 1)
        mask = torch.cat([mask, mask.new_ones((mask.shape[0], 1))], dim=1)
    else:
        ids, pos, tail = _right_aligned(new, read, pad_id)
        ids, pos = ids.to(dev), pos.to(dev)
        mask = torch.cat([mask, tail.to(mask.device)], dim=1)
    with grouped_heads(model) if most > 1 else nullcontext():
        out = model(input_ids=ids, attention_mask=mask, position_ids=pos, use_cache=True, **cache_arg(model, cache),
                    cache_position=torch.arange(width, width + most, device=dev), logits_to_keep=1)
    return out.logits[:, -1].float(), mask


def _right_aligned(chunks: list, starts: list, pad_id: int) -> tuple:
    """Rows' new tokens right-aligned and left-padded to the longest: (ids, position ids from each
    row's `start`, attention-mask tail with 0 on the padding), each [B, longest], on the CPU."""
    most = max(len(c) for c in chunks)
    ids = torch.full((len(chunks), most), pad_id, dtype=torch.long)
    pos = torch.zeros((len(chunks), most), dtype=torch.long)
    tail = torch.zeros((len(chunks), most), dtype=torch.long)
    for k, (tokens, start) in enumerate(zip(chunks, starts, strict=True)):
        n = len(tokens)
        ids[k, most - n:] = torch.tensor(tokens, dtype=torch.long)
        pos[k, most - n:] = torch.arange(start, start + n)
        tail[k, most - n:] = 1
    return ids, pos, tail


def loop_supported(model) -> bool:
    """Whether this loop handles the model's cache (plain dynamic layers: no sliding windows, no
    recurrent state); other models go through `model.generate`."""
    try:
        cache = DynamicCache(config=model.config)
    except Exception:  # noqa: BLE001 - any model whose cache we cannot build takes the generic path
        return False
    return bool(cache.layers) and all(type(layer) is DynamicLayer for layer in cache.layers)


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
