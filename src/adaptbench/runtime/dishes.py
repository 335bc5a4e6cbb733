"""Served dishes: what stands on a dining place at the end, with every ingredient traced back."""

from __future__ import annotations

from dataclasses import dataclass, field

from .world import Node, World


@dataclass
class Dish:
    """A served container (or an edible object put on a dining place directly)."""

    key: str
    container: str | None
    place: str
    served_step: int
    leaves: list = field(default_factory=list)  # (node, heated_on_path, cut_on_path)
    derived: list = field(default_factory=list)  # result nodes in its history
    vessels: set = field(default_factory=set)
    completes: set = field(default_factory=set)


def dining_place(world: World, eid: str) -> str | None:
    """The dining place `eid` stands on (at any depth), or None."""
    for a in world.ancestors(eid):
        if "dining_place" in world.specs[a].tags:
            return a
    return None


def served_dishes(world: World) -> list:
    """Every served dish, in a stable order."""
    dishes = []
    places = [e for e, s in world.specs.items() if "dining_place" in s.tags]
    on_places = sorted(d for p in places for d in world.descendants(p))
    for eid in on_places:
        spec = world.specs[eid]
        if spec.kind != "movable":
            continue
        place = dining_place(world, eid)
        if eid in world.nodes:
            if world.parent[eid] == place:
                dishes.append(_dish(world, eid, None, place, [world.nodes[eid]]))
            continue
        tops = list(world.contents.get(eid, ())) + [world.nodes[c] for c in world.children[eid] if c in world.nodes]
        if tops:
            dishes.append(_dish(world, eid, eid, place, tops))
    return dishes


def _dish(world: World, key: str, container: str | None, place: str, tops: list) -> Dish:
    step = max([world.arrived.get(key, 0)] + [t.arrived for t in tops])
    dish = Dish(key, container, place, step)
    for t in tops:
        _visit(dish, t, False, False)
    return dish


def _visit(dish: Dish, node: Node, heated: bool, cut: bool) -> None:
    heated = heated or bool(node.heated)
    cut = cut or node.cut
    dish.vessels.update(node.vessels)
    if not node.inputs:
        dish.leaves.append((node, heated, cut))
        return
    dish.derived.append(node)
    for i in node.inputs:
        _visit(dish, i, heated, cut)
