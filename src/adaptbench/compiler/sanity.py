"""Checks that keep hostile specs from hanging or crashing later passes: location cycles (every
holder chain must end in a room) and action message templates (only the action's slots, well-formed
braces, no attribute access or format specs: they are filled with `str.format` at run time)."""

from __future__ import annotations

import string

from .build import Draft
from .model import Where


def _where(draft: Draft, *keys) -> Where:
    for k in keys:
        if k in draft.where:
            return draft.where[k]
    return Where("<spec>", 1, 1)


def check_location_cycles(draft: Draft) -> bool:
    """D150 for every cycle of `location`s; True if there is none."""
    parent = {e.id: e.location for e in draft.entities if e.kind != "room" and e.location != e.id}
    state: dict = {}  # id -> 1 on the current walk, 2 done
    found = []
    for start in parent:
        walk, node = [], start
        while node in parent and node not in state:
            state[node] = 1
            walk.append(node)
            node = parent[node]
        if state.get(node) == 1:  # closed a cycle on this walk
            found.append(walk[walk.index(node):])
        for n in walk:
            state[n] = 2
    for cycle in found:
        first = min(cycle)
        i = cycle.index(first)
        ring = cycle[i:] + cycle[:i]
        draft.error(_where(draft, ("entity", first, "location"), ("entity", first)), "D150",
                    f"location cycle: {' -> '.join(ring + [first])} (every object must end up in a room)")
    return not found


def _template_problem(text: str, slots: set) -> str | None:
    try:
        parts = list(string.Formatter().parse(text))
    except ValueError as exc:
        return f"broken braces ({exc}; write {{{{ and }}}} for literal braces)"
    for _, name, spec, conv in parts:
        if name is None:
            continue
        if name not in slots:
            known = ", ".join("{" + s + "}" for s in sorted(slots)) or "none"
            return f"unknown slot {{{name}}} (the action's slots: {known})"
        if spec or conv:
            return f"{{{name}}} takes no conversion or format spec"
    return None


def check_templates(draft: Draft) -> None:
    """D151 for a success or failure message that names an unknown slot or has broken braces."""
    for a in draft.actions:
        slots = {name for name, _ in a.slots}
        texts = [("success message", a.success)] + [("failure message", p.fail) for p in a.preconditions]
        for what, text in texts:
            problem = _template_problem(str(text), slots)
            if problem:
                draft.error(_where(draft, ("action", a.id)), "D151", f"action '{a.id}': {what}: {problem}")
