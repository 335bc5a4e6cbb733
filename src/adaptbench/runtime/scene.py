"""Seeded scene sampling: every room, furniture item and mandatory object; each other movable
with probability 0.7. An object whose holder was left out is put in the nearest holder present."""

from __future__ import annotations

import hashlib
import random
from dataclasses import dataclass

from ..compiler.model import CompiledDomain

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


_SCENES: dict = {}


def sample_scene(domain: CompiledDomain, seed: int | None = 0, full: bool = False) -> Scene:
    """Sample a scene reproducibly from `seed` (or include everything when `full`); memoised."""
    key = (id(domain), seed, full)
    hit = _SCENES.get(key)
    if hit is None or hit[0] is not domain:
        if len(_SCENES) > 4096:
            _SCENES.clear()
        hit = (domain, _sample(domain, seed, full))
        _SCENES[key] = hit
    return hit[1]


def _sample(domain: CompiledDomain, seed: int | None, full: bool) -> Scene:
    rng = random.Random(seed)
    present = set()
    for e in domain.entities:  # catalogue order keeps the draw sequence stable
        keep = full or e.kind != "movable" or e.mandatory or rng.random() < KEEP_PROBABILITY
        if keep:
            present.add(e.id)
    _keep_required(domain, present)
    location = tuple((e.id, _holder(domain, e.id, present)) for e in domain.entities if e.id in present)
    digest = hashlib.sha256(f"{domain.spec_hash}:{seed}:{full}".encode()).hexdigest()[:12]
    return Scene(f"scene-{digest}", seed, full, frozenset(present), location)


def _provides(domain: CompiledDomain, e, cls: str) -> bool:
    if cls == e.category or cls in e.tags:
        return True
    return any(cls == domain.substance[c].category or cls in domain.substance[c].tags for c in e.contents)


def _keep_required(domain: CompiledDomain, present: set) -> None:
    """Every class a component requires keeps at least one provider (the first in the catalogue)."""
    for comp in domain.components:
        for cls in comp.requires:
            movables = [e for e in domain.entities if e.kind == "movable" and _provides(domain, e, cls)]
            if movables and not any(e.id in present for e in movables):
                present.add(movables[0].id)


def _holder(domain: CompiledDomain, eid: str, present: set) -> str | None:
    loc = domain.entity[eid].location
    while loc is not None and loc not in present:
        loc = domain.entity[loc].location
    return loc
