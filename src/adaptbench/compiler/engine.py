"""Checks of what the engine relies on: spec/engine.yaml itself, component kinds, effect parameter
values (states, verbs, verb groups, entities, search classes), the cross-validation splits of
spec/splits.yaml and persona numbers. Codes D205, D303, D501-D502, D601-D602 (docs/errors.md)."""

from __future__ import annotations

import re

from .build import Draft
from .diagnostics import did_you_mean
from .model import Where

_SLOT = re.compile(r"\{(\w+)\}")
_ENTITY_PARAMS = ("target", "item", "source", "place", "container")


def _where(draft: Draft, *keys) -> Where:
    for k in keys:
        if k in draft.where:
            return draft.where[k]
    return Where("<spec>", 1, 1)


def check_engine(draft: Draft) -> None:
    """The engine vocabulary names declared tags and categories, and every component kind is declared."""
    eng = draft.engine
    if eng is None:
        return
    if eng.dining_place not in draft.tags:
        draft.error(_where(draft, ("engine", "dining_place")), "D502",
                    f"dining_place '{eng.dining_place}' is not a declared tag{did_you_mean(eng.dining_place, draft.tags)}")
    for key in ("result_tags", "search_ignores"):
        for j, tag in enumerate(getattr(eng, key)):
            if tag not in draft.tags:
                draft.error(_where(draft, ("engine", key, j)), "D502",
                            f"{key}: '{tag}' is not a declared tag{did_you_mean(tag, draft.tags)}")
    _check_categories(draft, eng)
    classes = set(draft.tags) | set(draft.categories)
    for j, fam in enumerate(eng.swap_families):
        if fam not in classes:
            draft.error(_where(draft, ("engine", "swap_families", j)), "D502",
                        f"swap family '{fam}' is not a declared tag or category{did_you_mean(fam, classes)}")
    _unique(draft, [(k, ("engine", "kinds", g, j)) for g, ks in (("food", eng.food_kinds), ("drink", eng.drink_kinds))
                    for j, k in enumerate(ks)], "kind")
    _unique(draft, [(s, ("engine", "states", j)) for j, pair in enumerate(eng.states) for s in pair], "state")
    _check_kinds(draft, eng)


def _check_categories(draft: Draft, eng) -> None:
    """`cold_places` and `water` name declared categories."""
    named = [(cat, ("engine", "cold_places", j), "cold_places") for j, cat in enumerate(eng.cold_places)]
    named.append((eng.water, ("engine", "water"), "water"))
    for cat, key, what in named:
        if cat not in draft.categories:
            draft.error(_where(draft, key), "D502",
                        f"{what}: '{cat}' is not a declared category{did_you_mean(cat, draft.categories)}")


def _check_kinds(draft: Draft, eng) -> None:
    for c in draft.components:
        if c.kind not in eng.kinds:
            draft.error(_where(draft, ("component", c.id)), "D502",
                        f"component '{c.id}': unknown kind '{c.kind}'{did_you_mean(c.kind, eng.kinds)}"
                        f" (kinds are declared in spec/engine.yaml: {', '.join(eng.kinds)})")
        if c.alt_kind is not None and c.alt_kind not in eng.food_kinds:
            draft.error(_where(draft, ("component", c.id)), "D502",
                        f"component '{c.id}': kind_if kind '{c.alt_kind}' is not a food kind"
                        f"{did_you_mean(c.alt_kind, eng.food_kinds)} (one of: {', '.join(eng.food_kinds)})")


def _unique(draft: Draft, names: list, what: str) -> None:
    seen: set = set()
    for name, key in names:
        if name in seen:
            draft.error(_where(draft, key), "D502", f"{what} '{name}' is declared twice in spec/engine.yaml")
        seen.add(name)


# ---------------------------------------------------------------- effect parameter values
def check_effect_values(draft: Draft) -> None:
    """Literal effect parameters name declared things: `set_state` a state, `verb` a verb, `heat`/`cut`
    `always` or a verb group, entity parameters an entity, a `reveal_category` query a class."""
    verbs = {v for vs in draft.verb_groups.values() for v in vs} | set(draft.engine.action_verbs if draft.engine else ())
    flags = {"always"} | set(draft.verb_groups)
    entities = {e.id for e in draft.entities}
    classes = set(draft.tags) | set(draft.categories) | {s.id for s in draft.substances}
    states = set(draft.engine.state_names) if draft.engine else None
    for a in draft.actions:
        for j, eff in enumerate(a.effects):
            for k, v in eff.params:
                if _SLOT.fullmatch(v):
                    continue
                pool, what = _pool(eff.primitive, k, states, verbs, flags, entities, classes)
                if pool is not None and v not in pool:
                    draft.error(_where(draft, ("effect", a.id, j, k), ("effect", a.id, j)), "D205",
                                f"effect '{eff.primitive}': {k} '{v}' is not {what}{did_you_mean(v, pool)}")


def _pool(prim: str, param: str, states, verbs, flags, entities, classes) -> tuple:
    if prim == "set_state" and param == "state":
        return states, "a state declared in spec/engine.yaml"
    if param == "verb":
        return verbs, "a declared verb (spec/actions/verbs.yaml or action_verbs in spec/engine.yaml)"
    if param in ("heat", "cut"):
        return flags, "'always' or a verb group of spec/actions/verbs.yaml"
    if param in _ENTITY_PARAMS:
        return entities, "a slot or a declared entity"
    if param == "query":
        return classes, "a slot or a declared category, tag or substance"
    return None, ""


# ---------------------------------------------------------------- splits and personas
def check_splits(draft: Draft) -> None:
    """Splits name declared personas; every persona is unseen in exactly one split."""
    if not draft.splits:
        return
    personas = {p.id for p in draft.personas}
    where_unseen: dict = {}
    for sp in draft.splits:
        for j, pid in enumerate(sp.unseen):
            here = _where(draft, ("split", sp.id, j))
            if pid in draft.broken:
                continue
            if pid not in personas:
                draft.error(here, "D601", f"split {sp.id}: unknown persona '{pid}'{did_you_mean(pid, personas)}")
            elif pid in where_unseen:
                first = where_unseen[pid]
                draft.error(here, "D602", f"persona '{pid}' is unseen in split {first[0]} and again in split "
                                          f"{sp.id} (every persona is unseen in exactly one split)")
            else:
                where_unseen[pid] = (sp.id, here)
    for p in draft.personas:
        if p.id not in where_unseen:
            splits_at = _where(draft, ("splits",))
            draft.error(_where(draft, ("persona", p.id)), "D602",
                        f"persona '{p.id}' is unseen in no split: add it to one split of {splits_at.file}")


def check_persona_numbers(draft: Draft) -> None:
    """Persona numbers (the paper's numbering) are unique."""
    first: dict = {}
    for p in draft.personas:
        key = ("persona", p.id, "number")
        if key not in draft.where:
            continue
        if p.number in first:
            draft.error(draft.where[key], "D303", f"persona number {p.number} is already used by '{first[p.number]}'")
        else:
            first[p.number] = p.id
