"""Per-domain tables the runtime derives from a `CompiledDomain`, built once and kept with the domain
(`domain.derived`), never in module caches keyed by `id()`:

- `rooms`: the room ids (class expressions naming a room);
- `search_keys`, `search_index`: the words `Look for` matches each catalogue entity by, and inverted;
- `substances_by_category`: substance ids per category (planners looking for "a cheese");
- `scenes`: sampled scenes by (seed, full), an LRU; `world_templates`: what every episode on a scene
  starts from, an LRU by scene id;
- `rules`: compiled rule expressions by (rule, part); `per_dish`: whether a rule's scope condition
  is checked per dish; `available`: availability predicates by (predicate, scene id) — bounded LRUs
  keyed by the rule object (`IdentityLRU`), so rules made outside the domain (tests, tools) are
  cached too, boundedly.

    tables = domain_tables(domain)     # light: no parser is built (see runtime.index for that)
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field

from ..compiler.model import CompiledDomain


class LRU:
    """A small least-recently-used map with a size bound."""

    __slots__ = ("_data", "maxsize")

    def __init__(self, maxsize: int):
        self._data: OrderedDict = OrderedDict()
        self.maxsize = maxsize

    def get(self, key, default=None):
        """The value for `key` (marking it recently used), or `default`."""
        data = self._data
        if key in data:
            data.move_to_end(key)
            return data[key]
        return default

    def put(self, key, value):
        """Store `value` under `key`, evicting the least recently used entry beyond the bound; returns `value`."""
        data = self._data
        data[key] = value
        data.move_to_end(key)
        if len(data) > self.maxsize:
            data.popitem(last=False)
        return value

    def get_or_build(self, key, build):
        """The value for `key`, built by `build()` and stored on a miss."""
        hit = self.get(key, _MISSING)
        return self.put(key, build()) if hit is _MISSING else hit

    def clear(self) -> None:
        """Forget every entry."""
        self._data.clear()

    def __len__(self) -> int:
        return len(self._data)


_MISSING = object()


class IdentityLRU(LRU):
    """An LRU keyed by an object's identity plus an optional extra key, for values derived from
    immutable objects that are expensive to hash by value (rule trees). Each entry holds the object
    itself, so its id cannot be reused by another object while the entry lives, and the bound keeps
    the table small: unlike a module cache keyed by `id()`, it is neither unbounded nor global."""

    __slots__ = ()

    def get_or_build(self, key, build, extra=None):
        """The value derived from object `key` (and `extra`), built by `build()` on a miss."""
        k = (id(key), extra)
        hit = LRU.get(self, k)
        if hit is not None and hit[0] is key:
            return hit[1]
        return self.put(k, (key, build()))[1]


@dataclass(eq=False)
class DomainTables:
    """The runtime's derived tables for one domain (see the module docstring)."""

    domain: CompiledDomain
    rooms: frozenset
    substances_by_category: dict
    search_keys: dict = field(default_factory=dict)  # filled by runtime.effects on first `Look for`
    search_index: dict = field(default_factory=dict)
    scenes: LRU = field(default_factory=lambda: LRU(4096))
    world_templates: LRU = field(default_factory=lambda: LRU(1024))
    rules: IdentityLRU = field(default_factory=lambda: IdentityLRU(4096))
    per_dish: IdentityLRU = field(default_factory=lambda: IdentityLRU(4096))
    available: IdentityLRU = field(default_factory=lambda: IdentityLRU(65536))


def build_tables(domain: CompiledDomain) -> DomainTables:
    """Derive a domain's tables (prefer `domain_tables`, which keeps them with the domain)."""
    by_category: dict = {}
    for s in domain.substances:
        by_category.setdefault(s.category, []).append(s.id)
    return DomainTables(domain, frozenset(e.id for e in domain.entities if e.kind == "room"),
                        {c: tuple(ids) for c, ids in by_category.items()})


def domain_tables(domain: CompiledDomain) -> DomainTables:
    """The tables of a domain, built on first use and kept with the domain."""
    return domain.derived("runtime.tables", build_tables)
