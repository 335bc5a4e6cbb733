"""Class expressions (`milk & !plant_based`, `heated cheese`) compiled to fast Python predicates.

Two kinds of things are matched: provenance nodes (ingredients) and entities (places, containers,
cookware). A name matches by category, tag, id/name, or (for entities) the room they are in.
Modifiers `heated`/`chopped` need the path an ingredient took; node matchers therefore take
`(node, heated, cut)` where the flags say whether the path into the dish heated or cut it.
"""

from __future__ import annotations

from ..compiler import ast as A
from .tables import domain_tables


def node_matcher(cls):
    """Compile a class expression to `f(node, heated, cut) -> bool`."""
    if isinstance(cls, A.ClsName):
        n = cls.name
        return lambda node, h, c: n == node.category or n in node.tags or n == node.name or n == node.entity
    if isinstance(cls, A.ClsAny):
        fs = [node_matcher(x) for x in cls.items]
        return lambda node, h, c: any(f(node, h, c) for f in fs)
    if isinstance(cls, A.ClsAll):
        fs = [node_matcher(x) for x in cls.items]
        return lambda node, h, c: all(f(node, h, c) for f in fs)
    if isinstance(cls, A.ClsNeg):
        f = node_matcher(cls.item)
        return lambda node, h, c: not f(node, h, c)
    if isinstance(cls, A.ClsMod):
        f = node_matcher(cls.item)
        if cls.mod == "heated":
            return lambda node, h, c: h and f(node, h, c)
        return lambda node, h, c: c and f(node, h, c)
    raise TypeError(cls)


def _rooms(domain) -> frozenset:
    return domain_tables(domain).rooms


def entity_matcher(cls):
    """Compile a class expression to `f(world, entity_id) -> bool`."""
    if isinstance(cls, A.ClsName):
        n = cls.name

        def match(world, eid):
            spec = world.specs.get(eid)
            if spec is None:
                return False
            if n == eid or n == spec.category or n in spec.tags:
                return True
            return spec.kind != "room" and n in _rooms(world.domain) and world.room_of(eid) == n
        return match
    if isinstance(cls, A.ClsAny):
        fs = [entity_matcher(x) for x in cls.items]
        return lambda w, e: any(f(w, e) for f in fs)
    if isinstance(cls, A.ClsAll):
        fs = [entity_matcher(x) for x in cls.items]
        return lambda w, e: all(f(w, e) for f in fs)
    if isinstance(cls, A.ClsNeg):
        f = entity_matcher(cls.item)
        return lambda w, e: not f(w, e)
    if isinstance(cls, A.ClsMod):
        return entity_matcher(cls.item)
    raise TypeError(cls)


render = A.render_cls  # class expression back to text
