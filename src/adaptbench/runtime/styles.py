"""Styles decided by process (spec/tasks/styles.yaml): which verbs touched an ingredient before and after it
was first heated, whether water cooked it, what it was combined with. The `to get` name never counts.

A *path* is the chain of provenance nodes from one ingredient (a leaf) up to the top of the dish.
"""

from __future__ import annotations

from .world import Node


def _split(value: str) -> tuple:
    return tuple(v.strip() for v in value.split("|"))


def _matches(node: Node, names: tuple) -> bool:
    return any(n == node.category or n in node.tags or n == node.name for n in names)


def _paths(node: Node, trail: tuple = ()):
    """Every leaf-to-top chain under `node` (the top last)."""
    trail = (node,) + trail
    if not node.inputs:
        yield trail
        return
    for i in node.inputs:
        yield from _paths(i, trail)


def _first_heat(path: tuple) -> int | None:
    steps = [s for n in path for s in n.heated]
    return min(steps) if steps else None


def _verbs(domain, groups: str) -> frozenset:
    out: frozenset = frozenset()
    for g in _split(groups):
        out = out | domain.process.get(g, frozenset())
    return out


def _applied(path: tuple, verbs: frozenset, heat: int, after: bool) -> bool:
    """Whether a step on the path used one of `verbs` after (or before) the first heat."""
    return any(n.verb in verbs and (n.created >= heat if after else n.created < heat) for n in path[1:])


def _in_water(path: tuple, water: str) -> bool:
    """Whether a step that heated it had water as a direct input, or it was heated whole in water."""
    return any(n.wet for n in path) or \
        any(n.heated and any(not i.inputs and i.category == water for i in n.inputs) for n in path[1:])


def _chilled(path: tuple, heat: int | None) -> bool:
    """Whether it was put in a fridge after it was last heated (at any time if never heated)."""
    last = max((s for n in path for s in n.heated), default=None) if heat is not None else None
    return any(last is None or c >= last for n in path for c in n.chilled)


def _heated_after_added(path: tuple) -> bool:
    """Whether a step heated it, or a dish it went into, after it was last put into a container."""
    added = path[0].arrived
    return any(s >= added for n in path for s in n.heated)


def _flag(value) -> bool:
    return value is True or str(value).lower() in ("true", "yes")


# keys that are about a heated ingredient (an alternative with any of them needs one)
_HEAT_KEYS = ("medium", "before_heat", "not_before_heat", "while_hot", "not_while_hot")


def _with(path: tuple, names: tuple) -> bool:
    leaf = path[0]
    return any(p[0] is not leaf and _matches(p[0], names) for n in path[1:] for p in _paths(n))


def _path_ok(domain, path: tuple, alt: dict) -> bool:
    if "food" in alt and not _matches(path[0], _split(alt["food"])):
        return False
    heat = _first_heat(path)
    chilled = alt.get("chilled")
    if heat is None and (any(k in alt for k in _HEAT_KEYS) or (chilled is not None and not _flag(chilled))):
        return False
    if chilled is not None and _chilled(path, heat) != _flag(chilled):
        return False
    if "heated_after_added" in alt and _heated_after_added(path) != _flag(alt["heated_after_added"]):
        return False
    if "made_by" in alt and not any(n.verb in _verbs(domain, alt["made_by"]) for n in path[1:]):
        return False
    if heat is None:
        return "with" not in alt or _with(path, _split(alt["with"]))
    medium = alt.get("medium")
    if medium is not None and _in_water(path, domain.engine.water) != (medium == "water"):
        return False
    for key, after, want in (("before_heat", False, True), ("not_before_heat", False, False),
                             ("while_hot", True, True), ("not_while_hot", True, False)):
        if key in alt and _applied(path, _verbs(domain, alt[key]), heat, after) != want:
            return False
    return "with" not in alt or _with(path, _split(alt["with"]))


def process_ok(domain, tops: list, process: tuple) -> bool:
    """Whether some ingredient of the dish (reached from its `tops`) was made by one process alternative."""
    alts = [dict(a) for a in process]
    for top in tops:
        for path in _paths(top):
            if any(_path_ok(domain, path, alt) for alt in alts):
                return True
    return False
