"""The effect primitives action specs are written in. Each one changes the world and may return
an observation that replaces the action's `success` text (searches, questions)."""

from __future__ import annotations

import re
from functools import lru_cache

from ..compiler.model import EntitySpec
from .actions import ActionFailed, Ref
from .observe import found
from .tables import domain_tables
from .world import World


def _arg(params: dict, b: dict, name: str):
    """The value of an effect parameter: a bound slot for `{slot}`, else the literal text."""
    value = params.get(name)
    if value is None:
        return None
    m = re.fullmatch(r"\{(\w+)\}", value)
    return b[m.group(1)] if m else value


def _ent(params, b, name) -> str:
    ref = _arg(params, b, name)
    return ref.value if isinstance(ref, Ref) else ref


def reveal_in(world: World, params: dict, b: dict, ctx) -> str:
    """Search a place: everything in it (at any depth) becomes known."""
    place = _ent(params, b, "place")
    new = [e for e in world.descendants(place)]
    world.known.update(new)
    for e in new + [place]:
        world.known_contents.update(world.content_names(e))
    intro = f"{params['intro']} {place}. " if params.get("intro") else ""
    if not new:
        names = world.content_names(place)
        inside = f"{place} contains {', '.join(names)}" if names else f"Found nothing in/on {place}"
        return intro + inside
    return intro + found(world, new)


_PLURAL = [("ies", "y"), ("oes", "o"), ("ches", "ch"), ("shes", "sh"), ("ses", "s"), ("ves", "f"), ("ves", "fe"),
           ("s", "")]


@lru_cache(maxsize=8192)
def _stems(word: str) -> frozenset:
    out = {word}
    for suffix, repl in _PLURAL:
        if word.endswith(suffix) and len(word) > len(suffix) + 2:
            out.add(word[: -len(suffix)] + repl)
    return frozenset(out)


@lru_cache(maxsize=4096)
def _query_words(query: str) -> frozenset:
    words = re.findall(r"[a-z]+", query.lower().replace("_", " "))
    words = [w for w in words if w not in ("a", "an", "the", "some", "of")]
    key = "_".join(words)
    return _stems(key) | (frozenset(s for w in words for s in _stems(w)) if len(words) == 1 else frozenset())




def _static_keys(spec, domain) -> frozenset:
    generic = set(domain.engine.search_ignores)
    keys = {spec.category} | (set(spec.tags) - generic)
    keys |= {t.rsplit("_", 1)[1] for t in spec.tags if "_" in t}  # breakfast_cereal -> cereal
    keys |= {s for w in re.findall(r"[a-z]+", spec.description.lower()) for s in _stems(w)}
    keys.add(spec.id.rsplit("_", 1)[0])
    for name in spec.contents:
        sub = domain.substance.get(name)
        keys.add(name)
        if sub:
            keys |= {sub.category} | (set(sub.tags) - generic)
            keys |= {t.rsplit("_", 1)[1] for t in sub.tags if "_" in t}
    return frozenset(keys)


def _index(domain) -> tuple:
    """(domain, entity -> keys, key -> catalogue entities), built once into the domain's tables."""
    tables = domain_tables(domain)
    if not tables.search_keys:
        keys = {e.id: _static_keys(e, domain) for e in domain.entities}
        inverted: dict = {}
        for e in domain.entities:
            if e.kind != "room":  # appliances and furniture too: `Look for kettle`
                for k in keys[e.id]:
                    inverted.setdefault(k, []).append(e.id)
        tables.search_index.update(inverted)
        tables.search_keys.update(keys)
    return domain, tables.search_keys, tables.search_index


def _search_keys(world: World, eid: str) -> frozenset:
    """Words `Look for` matches an entity by (cached per catalogue entity)."""
    domain = world.domain
    index = _index(domain)
    spec = world.specs[eid]
    keys = index[1].get(eid) if domain.entity.get(eid) is spec else None
    if keys is None:
        keys = _static_keys(spec, domain)
    extra = world.contents.get(eid)
    if extra:
        keys = keys | {n.name for n in extra} | {n.category for n in extra if n.category}
    return keys


def _matches_query(world: World, eid: str, keys: set) -> bool:
    return not keys.isdisjoint(_search_keys(world, eid))


def _lookup(world: World, keys: set) -> list:
    """Movables present now that match any key: the catalogue index, plus entities created or
    filled during the episode."""
    domain = world.domain
    inverted = _index(domain)[2]
    hits = {e for k in keys for e in inverted.get(k, ()) if world.specs.get(e) is domain.entity.get(e)}
    dynamic = [e for e in world.contents if e in world.specs] + [e for e in world.nodes if e not in domain.entity]
    hits.update(e for e in dynamic if world.specs[e].kind == "movable" and _matches_query(world, e, keys))
    return list(hits)


def _all_words(world: World, query: str) -> list:
    """Fallback for multi-word queries ('peanut butter'): movables whose description has every word."""
    words = [w for w in re.findall(r"[a-z]+", query.lower()) if w not in ("a", "an", "the", "some", "of")]
    if len(words) < 2:
        return []
    want = [_stems(w) for w in words]
    out = []
    for e, spec in world.specs.items():
        if spec.kind != "movable":
            continue
        have = {s for w in re.findall(r"[a-z]+", spec.description.lower()) for s in _stems(w)}
        if all(stems & have for stems in want):
            out.append(e)
    return out


def reveal_category(world: World, params: dict, b: dict, ctx) -> str:
    """Look for a category in the whole house; matches and their holders become known."""
    query = _arg(params, b, "query")
    keys = _query_words(query)
    hits = _lookup(world, keys) or _all_words(world, query)
    new, seen = [], set(world.known)
    for e in sorted(hits, key=_natural):
        for a in [*reversed(list(world.ancestors(e))), e]:
            if a not in seen:
                seen.add(a)
                new.append(a)
    world.known.update(new)
    for e in new:
        world.known_contents.update(world.content_names(e))
    if not hits:
        return f"Could not find any {_arg(params, b, 'query')}"
    return found(world, [e for e in new] or sorted(hits, key=_natural))


def _natural(eid: str):
    base, _, num = eid.rpartition("_")
    return (base, int(num)) if num.isdigit() else (eid, -1)


def set_state(world: World, params: dict, b: dict, ctx) -> None:
    """Set a state of an entity (open, on ...), clearing its opposite (spec/engine.yaml `states`)."""
    eid, state = _ent(params, b, "target"), params["state"]
    states = world.state.setdefault(eid, set())
    states.discard(world.domain.engine.opposite(state))
    states.add(state)


def took_part(world: World, node, vessels) -> None:
    """The vessels a node was heated or made in, and the utensils standing in them then, took part."""
    vessels = list(vessels)
    # the innermost vessel that is not food itself: the pan a whole tomato was heated in, not the tomato
    inner = [v for v in vessels if v not in world.nodes][:1]
    tools = [c for v in inner if v in world.specs and world.specs[v].kind == "movable"
             for c in world.children.get(v, ()) if c not in world.nodes and world.specs[c].kind == "movable"]
    node.vessels.update(vessels)
    node.vessels.update(tools)
    world.used.update(vessels)
    world.used.update(tools)


def _heat_node(world: World, node, vessels) -> None:
    node.heated.append(world.step)
    took_part(world, node, vessels)


def _heat_entity(world: World, eid: str) -> None:
    vessels = [eid, *world.ancestors(eid)]
    if eid in world.nodes:
        node = world.nodes[eid]
        _heat_node(world, node, vessels)
        if _in_water(world, world.parent.get(eid)):
            node.wet += (world.step,)  # a whole egg in a pot of water: boiled in its shell
    for n in world.contents.get(eid, ()):
        _heat_node(world, n, vessels)


def _in_water(world: World, holder: str | None) -> bool:
    """Whether `holder` holds water (an object in it sits in water)."""
    water = world.domain.engine.water
    return holder is not None and any(n.category == water for n in world.contents.get(holder, ()))


def _cold_ids(domain) -> frozenset:
    """The catalogue ids of cold furniture (kept with the domain)."""
    cold = frozenset(domain.engine.cold_places)
    return frozenset(e.id for e in domain.entities if e.category in cold)


def _is_cold(world: World, target: str) -> bool:
    cold = world.domain.derived("effects.cold_ids", _cold_ids)
    return bool(cold) and (target in cold or any(a in cold for a in world.ancestors(target)))


def _chill_entity(world: World, eid: str) -> None:
    """Everything edible in or on `eid` (and `eid` itself) was chilled now."""
    for e in (eid, *world.descendants(eid)):
        if e in world.nodes:
            world.nodes[e].chilled += (world.step,)
        for n in world.contents.get(e, ()):
            n.chilled += (world.step,)


def heat(world: World, params: dict, b: dict, ctx) -> None:
    """Heat one thing: an object, a container's contents, or one content."""
    ref = _arg(params, b, "target")
    if ref.kind == "content":
        vessels = [ref.holder, *world.ancestors(ref.holder)]
        for n in world.contents.get(ref.holder, ()):
            if n.name == ref.value:
                _heat_node(world, n, vessels)
        return
    _heat_entity(world, ref.value)
    for d in world.descendants(ref.value):
        _heat_entity(world, d)


def heat_all_in(world: World, params: dict, b: dict, ctx) -> None:
    """Heat everything in or on an appliance (turning it on)."""
    eid = _ent(params, b, "target")
    for d in [eid, *world.descendants(eid)]:
        _heat_entity(world, d)


def _into(world: World, target: str, what: str) -> None:
    spec = world.specs[target]
    if not world.is_container(target):
        raise ActionFailed(f"{target} is not a container: {what} must go into a container")
    if spec.kind == "furniture" and "appliance" not in spec.tags:
        raise ActionFailed(f"{target} is not something to pour into: {what} must go into a container"
                           f" standing there (a cup, bowl, pan, pot) or an appliance such as a kettle")


def move(world: World, params: dict, b: dict, ctx) -> None:
    """Move an object, or contents, to a target."""
    ref, target = _arg(params, b, "item"), _ent(params, b, "target")
    if ref.kind == "entity":
        world.relocate(ref.value, target)
        if _is_cold(world, target):
            _chill_entity(world, ref.value)
        return
    pour(world, params, b, ctx)


def pour(world: World, params: dict, b: dict, ctx) -> None:
    """Pour a content from one container into another."""
    ref, target = _arg(params, b, "item"), _ent(params, b, "target")
    _into(world, target, ref.value)
    nodes = world.take_contents(ref.holder, ref.value)
    world.put_contents(target, nodes)
    if _is_cold(world, target):
        for n in nodes:
            n.chilled += (world.step,)


def _applies(world: World, flag: str | None, verb: str) -> bool:
    if flag is None:
        return False
    return flag == "always" or world.domain.verbs.get(verb) == flag


def combine(world: World, params: dict, b: dict, ctx) -> None:
    """Turn everything edible in a container into one result content (mix, cook, freeform)."""
    container, result, verb = _ent(params, b, "container"), _arg(params, b, "result"), _arg(params, b, "verb")
    inputs = list(world.contents.get(container, ()))
    for child in list(world.children.get(container, ())):
        if child in world.nodes:
            inputs.append(world.nodes[child])
            world.remove(child)
    if not inputs:
        raise ActionFailed(f"{container} holds nothing to {verb} (endless supplies must be poured out first)")
    node = world.new_node(result, None, frozenset(world.domain.engine.result_tags), tuple(inputs), verb)
    took_part(world, node, [container, *world.ancestors(container)])
    node.arrived = min(n.arrived for n in inputs)
    world.contents[container] = [node]
    world.known_contents.add(result)
    if _applies(world, params.get("heat"), verb):
        _heat_node(world, node, [container, *world.ancestors(container)])


def transform(world: World, params: dict, b: dict, ctx) -> None:
    """Turn one thing into a result (chop, crack, peel ...): an object stays an object."""
    ref, result, verb = _arg(params, b, "item"), _arg(params, b, "result"), _arg(params, b, "verb")
    if ref.kind == "entity":
        _transform_object(world, ref.value, result, verb, params)
        return
    old = world.take_contents(ref.holder, ref.value)
    node = world.new_node(result, None, frozenset(world.domain.engine.result_tags), tuple(old), verb)
    _mark(world, node, params, verb, ref.holder)
    node.arrived = min(n.arrived for n in old)
    world.contents.setdefault(ref.holder, []).append(node)
    world.known_contents.add(result)


def _transform_object(world: World, eid: str, result: str, verb: str, params: dict) -> None:
    if eid not in world.nodes:
        raise ActionFailed(f"{eid} is not edible")
    where = world.parent[eid]
    old = world.nodes[eid]
    node = world.new_node(result, None, frozenset(world.domain.engine.result_tags), (old,), verb)
    node.arrived = old.arrived
    _mark(world, node, params, verb, where)
    desc = f"{verb} {world.specs[eid].description}"
    spec = EntitySpec(result, "movable", desc, "result", (*world.domain.engine.result_tags, "movable"), where)
    world.remove(eid)
    world.add_entity(spec, node, where)


def _mark(world: World, node, params: dict, verb: str, where: str) -> None:
    if _applies(world, params.get("cut"), verb):
        node.cut = True
    if _applies(world, params.get("heat"), verb):
        _heat_node(world, node, [where, *world.ancestors(where)])
    took_part(world, node, [where, *world.ancestors(where)])


def ask(world: World, params: dict, b: dict, ctx) -> str:
    """Ask the user a question; the reply is recorded on the step."""
    world.questions += 1
    ctx["reply"] = ctx["user"](question(params, b), dialogue(world)) if ctx.get("user") else ""
    return ""


def question(params: dict, b: dict) -> str:
    """The question an `ask` effect puts to the user, from its parameters and the step's bindings."""
    return _arg(params, b, "question")


def dialogue(world: World) -> tuple:
    """The questions asked so far and the replies they got: ((question, reply), ...). What a user
    answers from (never the simulator's state)."""
    return tuple((e.args.get("question", ""), e.reply) for e in world.trace if e.action == "ask" and e.ok)


def done(world: World, params: dict, b: dict, ctx) -> None:
    """End the episode."""
    world.done = True


PRIMITIVES = {"reveal_in": reveal_in, "reveal_category": reveal_category, "set_state": set_state,
              "heat": heat, "heat_all_in": heat_all_in, "move": move, "pour": pour, "combine": combine,
              "transform": transform, "ask": ask, "done": done}
