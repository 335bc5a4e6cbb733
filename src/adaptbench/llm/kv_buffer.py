"""Key/value cache layers written in place: a buffer with room to grow instead of a tensor concatenated
per token (`DynamicLayer`'s way), and the transformers cache object that holds them.

    layers = [BufferLayer(room=24) for _ in range(n_layers)]    # empty: the first update allocates
    cache = cache_of(layers, model.config)                      # what a model's forward takes
"""

from __future__ import annotations

import torch
from transformers import DynamicCache
from transformers.cache_utils import DynamicLayer

GROW = 4  # a buffer that must grow gains at least 1/GROW of its size (amortised: few copies per episode)


class BufferLayer(DynamicLayer):
    """A cache layer whose keys and values live in a buffer [B, heads, capacity, dim] with room to grow:
    a pass writes its positions in place after the first `n` instead of concatenating (copying) the
    whole cache, as `DynamicLayer` does every token. `keys`/`values` are views of the first `n`. A
    layer starts empty (its first update allocates), from a copy of given tensors with `room` more
    positions, or (`adopt`) on given tensors as its buffer."""

    def __init__(self, keys: torch.Tensor | None = None, values: torch.Tensor | None = None, room: int = 0,
                 adopt: bool = False):
        super().__init__()
        self._k = self._v = None
        self.n, self.room = 0, room
        if keys is None:
            return
        if adopt:
            self._k, self._v, self.n = keys, values, keys.shape[2]
        else:
            b, h, n, d = keys.shape
            self._k, self._v = keys.new_empty((b, h, n + room, d)), values.new_empty((b, h, n + room, d))
            self._k[:, :, :n], self._v[:, :, :n] = keys, values
            self.n = n
        self._ready()

    def _ready(self) -> None:
        self.dtype, self.device, self.is_initialized = self._k.dtype, self._k.device, True
        self._views()

    def _views(self) -> None:
        self.keys, self.values = self._k[:, :, :self.n], self._v[:, :, :self.n]

    def reserve(self, total: int) -> None:
        """Make room for `total` positions (one copy when the buffer is too small, none otherwise)."""
        if self._k is None or total <= self._k.shape[2]:
            return
        size = max(total, self._k.shape[2] + self._k.shape[2] // GROW)
        k = self._k.new_empty((*self._k.shape[:2], size, self._k.shape[3]))
        v = self._v.new_empty((*self._v.shape[:2], size, self._v.shape[3]))
        k[:, :, :self.n], v[:, :, :self.n] = self.keys, self.values
        self._k, self._v = k, v
        self._views()

    def truncate(self, n: int) -> None:
        """Keep the first `n` positions (later writes overwrite the rest)."""
        self.n = min(n, self.n)
        self._views()

    def update(self, key_states: torch.Tensor, value_states: torch.Tensor, *args, **kwargs) -> tuple:
        """Write the new positions after the cached ones; returns the cache so far."""
        q = key_states.shape[-2]
        if self._k is None:
            b, h, _, d = key_states.shape
            self._k = key_states.new_empty((b, h, q + self.room, d))
            self._v = value_states.new_empty((b, h, q + self.room, d))
            self._ready()
        self.reserve(self.n + q)
        self._k[:, :, self.n:self.n + q], self._v[:, :, self.n:self.n + q] = key_states, value_states
        self.n += q
        self._views()
        return self.keys, self.values

    def get_seq_length(self) -> int:
        """Positions cached."""
        return self.n

    def select(self, rows: torch.Tensor) -> None:
        """Keep only these batch rows (a copy of the kept rows)."""
        self._k, self._v = self._k[rows], self._v[rows]
        self._views()

    def row_parts(self, k: int, cached: int, width: int, new: int) -> BufferLayer:
        """Row k after a batched prefill: its `cached` positions before `width` and its `new` last ones,
        as a layer of its own (a copy)."""
        h, d = self._k.shape[1], self._k.shape[3]
        out = BufferLayer(self._k.new_empty((1, h, cached + new, d)), self._v.new_empty((1, h, cached + new, d)),
                          adopt=True)
        out.n = 0
        out.update(self.keys[k:k + 1, :, width - cached:width], self.values[k:k + 1, :, width - cached:width])
        out.update(self.keys[k:k + 1, :, self.n - new:], self.values[k:k + 1, :, self.n - new:])
        return out

    def row(self, k: int, where: torch.Tensor | None) -> BufferLayer:
        """Row k's cached positions `where` (its real ones, padding left out; None: all of them), as a
        layer of its own: a copy, except a batch of one unpadded, which is this layer."""
        if where is None:
            if self._k.shape[0] == 1:
                return self
            return BufferLayer(self.keys[k:k + 1], self.values[k:k + 1])
        where = where.to(self.keys.device)
        return BufferLayer(self.keys[k:k + 1, :, where], self.values[k:k + 1, :, where], adopt=True)


def cache_of(layers: list, config) -> DynamicCache:
    """A transformers cache whose layers are these `BufferLayer`s."""
    cache = DynamicCache(config=config)
    cache.layers = list(layers)
    return cache


class PackedRow:
    """One row's keys and values of every layer in one tensor [layers, 2, heads, n, dim]: what a
    session keeps after a decode in a `batch_pass.DecodeGraphs` pool (one copy out of the pool, and
    one back in at the episode's next step, instead of two per layer). Per-layer `BufferLayer`s are
    made only where a path needs them (`layers`)."""

    def __init__(self, data: torch.Tensor):
        self.data, self.n = data, data.shape[3]

    def __len__(self) -> int:
        return self.data.shape[0]

    def truncate(self, n: int) -> None:
        """Keep the first `n` positions."""
        self.n = min(n, self.n)

    def head(self, n: int) -> PackedRow:
        """A copy of the first `n` positions."""
        return PackedRow(self.data[:, :, :, :n].clone())

    def layers(self) -> list:
        """Per-layer `BufferLayer`s over this row's first `n` positions (views: a layer that must grow
        copies itself)."""
        d = self.data[:, :, :, :self.n].unsqueeze(3)  # [layers, 2, heads, 1, n, dim] -> batch axis
        return [BufferLayer(d[i, 0].transpose(0, 1), d[i, 1].transpose(0, 1), adopt=True) for i in range(len(self))]


def as_layers(cached) -> list | None:
    """Per-layer cache layers of a session's cache (a `PackedRow` unpacked; a list as it is)."""
    return cached.layers() if isinstance(cached, PackedRow) else cached
