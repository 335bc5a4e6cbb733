"""Observation text in the paper's format (`Found egg_0 (brown egg) in/on egg_carton_0, ...`)."""

from __future__ import annotations

from .world import World


def describe(world: World, eid: str) -> str:
    """`id (description, contains a, b)`."""
    spec = world.specs[eid]
    names = world.content_names(eid)
    extra = f", contains {', '.join(names)}" if names else ""
    return f"{eid} ({spec.description}{extra})"


def found(world: World, eids: list) -> str:
    """The observation listing newly seen entities and where they are."""
    if not eids:
        return "Found nothing"
    return "Found " + ", ".join(f"{describe(world, e)} in/on {world.parent[e]}" for e in eids)


def layout(world: World) -> str:
    """The house layout the agent starts with: rooms and their furniture."""
    lines = []
    for room in (e for e, s in world.specs.items() if s.kind == "room"):
        lines.append(f"- {room} ({world.specs[room].description})")
        for f in world.children[room]:
            if world.specs[f].kind == "furniture":
                lines.append(f"  - {describe(world, f)}")
    return "\n".join(lines)
