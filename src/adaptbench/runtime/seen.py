"""`Seen`: the part of an episode's world the agent has found, read-only.

What an agent may know without privileged access: the entities it has found (the layout, objects
it looked for, results it made), what category each is, where it is, and what it holds (sources seen
when found, portions it put there). Nothing about unfound objects, the persona or the verifiers.
Scripted agents plan from this (`View.seen`); a language model reads the same facts from the text.
"""

from __future__ import annotations

from .world import World


class Seen:
    """A read-only window on the known part of a `World` (valid for the step it was taken at)."""

    __slots__ = ("_w",)

    def __init__(self, world: World):
        self._w = world

    def knows(self, eid: str) -> bool:
        """Whether the agent has found entity `eid` (and it still exists)."""
        return eid in self._w.known

    def known(self):
        """The ids of every found entity (a set: iterate or test it, never change it)."""
        return self._w.known

    def category(self, eid: str) -> str | None:
        """The category of a found entity (None when not found)."""
        return self._w.specs[eid].category if eid in self._w.known else None

    def parent(self, eid: str) -> str | None:
        """Where a found entity is (None when not found)."""
        return self._w.parent.get(eid) if eid in self._w.known else None

    def holders_of(self, name: str) -> list:
        """Found entities holding content `name`, sorted."""
        return self._w.holders_of(name)

    def sources(self, eid: str) -> tuple:
        """The endless contents of a found entity (a milk carton's milk)."""
        return self._w.sources.get(eid, ()) if eid in self._w.known else ()

    def holds_food(self, eid: str) -> bool:
        """Whether a found entity holds something edible (contents, or an edible object on or in it)."""
        w = self._w
        if eid not in w.known:
            return False
        return bool(w.contents.get(eid)) or any(c in w.nodes for c in w.children.get(eid, ()))
