"""Seeded scene sampling: every room, furniture item and mandatory object; each other movable
with probability 0.7. An object whose holder was left out is put in the nearest holder present.

Stability: whether an optional object is present is decided by a hash of (seed, its id, its holder)
alone, never by catalogue order or a shared random stream, so adding, removing or reordering other
objects leaves every other object's presence unchanged. A component's required class that no drawn
object provides keeps the provider with the smallest draw (the same for every catalogue order). The
scene id is a hash of what the scene holds, so an unrelated spec edit keeps every scene id."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

from ..compiler.model import CompiledDomain
from .tables import domain_tables

KEEP_PROBABILITY = 0.7


@dataclass(frozen=True)
class Scene:
    """Which entities are present and where each starts."""

    scene_id: str
    seed: int | None
    full: bool
    present: frozenset
    location: tuple  # ((entity id, holder id or None), ...) in catalogue order

    def as_dict(self, domain: CompiledDomain) -> dict:
        """A JSON-friendly description: id, seed, and the objects with their locations."""
        return {"scene_id": self.scene_id, "seed": self.seed, "full": self.full,
                "counts": {"entities": len(self.present),
                           "movables": sum(domain.entity[e].kind == "movable" for e in self.present)},
                "objects": [{"id": e, "description": domain.entity[e].description, "location": loc,
                             "contents": list(domain.entity[e].contents)}
                            for e, loc in self.location]}


def sample_scene(domain: CompiledDomain, seed: int | None = 0, full: bool = False) -> Scene:
    """Sample a scene reproducibly from `seed` (or include everything when `full`); memoised in the
    domain's tables (an LRU)."""
    return domain_tables(domain).scenes.get_or_build((seed, full), lambda: _sample(domain, seed, full))


def _sample(domain: CompiledDomain, seed: int | None, full: bool) -> Scene:
    present = {e.id for e in domain.entities
               if full or e.kind != "movable" or e.mandatory or draw(seed, e.id, e.location) < KEEP_PROBABILITY}
    _keep_required(domain, seed, present)
    location = tuple((e.id, _holder(domain, e.id, present)) for e in domain.entities if e.id in present)
    return Scene(scene_id(domain, location), seed, full, frozenset(present), location)


def draw(seed: int | None, eid: str, holder: str | None) -> float:
    """The object's own uniform draw in [0, 1) for `seed`: a hash of (seed, id, holder) only."""
    digest = hashlib.blake2b(f"{seed}\x1f{eid}\x1f{holder}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "big") / 2**64


def scene_id(domain: CompiledDomain, location: tuple) -> str:
    """A hash of what the scene holds: each present entity's id, holder, description and contents."""
    held = sorted([eid, loc or "", domain.entity[eid].description, list(domain.entity[eid].contents)]
                  for eid, loc in location)
    return "scene-" + hashlib.sha256(json.dumps(held).encode()).hexdigest()[:12]


def _provides(domain: CompiledDomain, e, cls: str) -> bool:
    if cls == e.category or cls in e.tags:
        return True
    return any(cls == domain.substance[c].category or cls in domain.substance[c].tags for c in e.contents)


def _keep_required(domain: CompiledDomain, seed: int | None, present: set) -> None:
    """Every class a component requires keeps at least one provider: when none was drawn, the one
    with the smallest draw (independent of catalogue order)."""
    for comp in domain.components:
        for cls in comp.requires:
            movables = [e for e in domain.entities if e.kind == "movable" and _provides(domain, e, cls)]
            if movables and not any(e.id in present for e in movables):
                present.add(min(movables, key=lambda e: (draw(seed, e.id, e.location), e.id)).id)


def _holder(domain: CompiledDomain, eid: str, present: set) -> str | None:
    loc = domain.entity[eid].location
    while loc is not None and loc not in present:
        loc = domain.entity[loc].location
    return loc
