"""Served dishes as a person sees the table: what stands on a dining place at the end, every ingredient
traced back with how it arrived (made into the dish or put on it afterwards), when the dish reached the
table, and what is served alongside it (its sides).

Vocabulary (docs/rules.md, *The table as a person sees it*):
- a *piece* is one top-level thing in a dish's vessel: a poured/cooked content or an object placed in it;
- a *maker* piece is the product of cooking or mixing (a result whose verb is not a cutting verb) or a
  piece that was heated; the dish was *made* when its last maker arrived in the vessel;
- an object set on the plate that was not cooked with the dish (toast, half an avocado beside scrambled
  eggs), before or after the dish arrived, is *placed* on it: a side of it, not what made it;
- *topped with*: pieces that arrived after the dish was made (or, with no maker, after its first piece)
  and were not heated with it; *made with*: every other piece (the makers, what went in before them, what
  was heated in the vessel after it arrived) and, in a dish with no maker (cereal, parfait), every piece;
- water that only poached or boiled something (an input, with eggs, of a heated step) is a cooking
  medium, not an ingredient (`medium`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .world import Node, World

_EGGS = frozenset(("egg", "egg_substitute"))


@dataclass
class Dish:
    """A served container (or an edible object put on a dining place directly)."""

    key: str
    container: str | None
    place: str
    served_step: int
    leaves: list = field(default_factory=list)  # (node, heated_on_path, cut_on_path): what it has
    made: list = field(default_factory=list)  # leaves that went in while it was made
    topped: list = field(default_factory=list)  # leaves put on it after it was made
    placed: list = field(default_factory=list)  # leaves of objects placed on it after it was made (sides too)
    medium: list = field(default_factory=list)  # cooking water: made with, but no ingredient
    derived: list = field(default_factory=list)  # result nodes in its history
    tops: list = field(default_factory=list)  # its pieces (what the styles follow down)
    vessels: set = field(default_factory=set)
    completes: set = field(default_factory=set)
    as_is: bool = False  # a condiment / milk container served as it is (only ever a side)
    water: str = "water"  # the domain's water category (engine vocabulary)


def dining_place(world: World, eid: str) -> str | None:
    """The dining place `eid` stands on (at any depth), or None."""
    tag = world.domain.engine.dining_place
    for a in world.ancestors(eid):
        if tag in world.specs[a].tags:
            return a
    return None


def _reached(world: World, eid: str, place: str) -> int:
    """The step `eid` reached `place`: the last arrival of it or anything carrying it (a tray)."""
    step = world.arrived.get(eid, 0)
    for a in world.ancestors(eid):
        if a == place:
            break
        step = max(step, world.arrived.get(a, 0))
    return step


def served_dishes(world: World) -> list:
    """Every served dish, in a stable order (as-is condiment containers are not among them)."""
    return [d for d in table(world) if not d.as_is]


def table(world: World) -> list:
    """Every dish and every as-is container (ketchup bottle, milk jug) standing on a dining place."""
    dishes = []
    tag = world.domain.engine.dining_place
    places = [e for e, s in world.specs.items() if tag in s.tags]
    on_places = sorted(d for p in places for d in world.descendants(p))
    for eid in on_places:
        if world.specs[eid].kind != "movable":
            continue
        place = dining_place(world, eid)
        if eid in world.nodes:
            if world.parent[eid] == place:
                dishes.append(_dish(world, eid, None, place, [world.nodes[eid]]))
            continue
        tops = list(world.contents.get(eid, ())) + [world.nodes[c] for c in world.children[eid] if c in world.nodes]
        if tops:
            dishes.append(_dish(world, eid, eid, place, tops))
        elif world.sources.get(eid):
            dishes.append(_as_is(world, eid, place))
    return dishes


def _as_is(world: World, eid: str, place: str) -> Dish:
    dish = Dish(eid, eid, place, _reached(world, eid, place), as_is=True)
    for sub in world.sources[eid]:
        s = world.domain.substance[sub]
        leaf = (Node(0, sub, s.category, frozenset(s.tags)), False, False)
        dish.leaves.append(leaf)
        dish.made.append(leaf)
    return dish


def _is_maker(world: World, node: Node) -> bool:
    if node.heated:
        return True
    return bool(node.inputs) and node.verb != "chop" and world.domain.verbs.get(node.verb) != "cutting"


def _set_beside(world: World, tops: list, here: dict) -> tuple:
    """(makers, beside): a dish cooked here or poured in cooked (scrambled eggs) is made by those pieces; food
    set on the same plate that was not cooked with it (a slice of toast heated elsewhere, half an avocado),
    before or after it, is beside it, i.e. a side; what is sprinkled or poured on it cold (salt, cilantro)
    stays a topping. A plate of such pieces only (toast, avocado toast) is made by them as before."""
    makers = [t for t in tops if _is_maker(world, t)]
    cooked = [t for t in makers if t.inputs or here[t.nid]]  # mixed or cooked food, or heated in this vessel
    if not cooked:
        return makers, []
    return cooked, [t for t in tops if t not in cooked and not here[t.nid] and (t.entity is not None or t.heated)]


def _dish(world: World, key: str, container: str | None, place: str, tops: list) -> Dish:
    tops = sorted(tops, key=lambda t: (t.arrived, t.nid))
    here = {t.nid: any(h >= t.arrived for h in t.heated) for t in tops}  # heated in this vessel
    makers, beside = _set_beside(world, tops, here)
    base = makers[-1] if makers else tops[0]
    dish = Dish(key, container, place, max(_reached(world, key, place), base.arrived), tops=tops,
                water=world.domain.engine.water)
    for t in tops:
        leaves = _leaves(dish, t)
        heated_here = here[t.nid]
        if t in beside and t.arrived <= base.arrived:  # set down before the dish came: still beside it
            dish.placed.extend(leaves)
        if t is not base and t.arrived > base.arrived and not heated_here and t not in makers:
            dish.topped.extend(leaves)
            if t.entity is not None or t in beside:
                dish.placed.extend(leaves)
            if makers:
                continue
        dish.made.extend(leaves)
    return dish


def _leaves(dish: Dish, top: Node) -> list:
    out: list = []
    _visit(dish, top, False, False, out)
    return out


def _visit(dish: Dish, node: Node, heated: bool, cut: bool, out: list) -> None:
    heated = heated or bool(node.heated)
    cut = cut or node.cut
    dish.vessels.update(node.vessels)
    if not node.inputs:
        out.append((node, heated, cut))
        dish.leaves.append((node, heated, cut))
        return
    dish.derived.append(node)
    medium = _cooking_water(node, dish.water)
    for i in node.inputs:
        if i in medium:
            dish.medium.append((i, True, False))
            out.append((i, True, False))
            continue
        _visit(dish, i, heated, cut, out)


def _cooking_water(node: Node, category: str) -> tuple:
    """Water that only poached or boiled eggs in this heated step (not water made into the food)."""
    if not node.heated:
        return ()
    water = tuple(i for i in node.inputs if not i.inputs and i.category == category)
    if water and any(_has_egg(i) for i in node.inputs if i not in water):
        return water
    return ()


def _has_egg(node: Node) -> bool:
    if not node.inputs:
        return node.category in _EGGS or not _EGGS.isdisjoint(node.tags)
    return any(_has_egg(i) for i in node.inputs)
