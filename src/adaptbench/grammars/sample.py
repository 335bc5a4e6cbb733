"""A random sampler over the grammar IR: strings of the language of a state's grammar (for tests:
every sampled string must be understood by the simulator and accepted by every engine)."""

from __future__ import annotations

import random

from .emit import Observed
from .index import GrammarIndex, Lit, Slot

_WORDS = ("how", "do", "you", "like", "your", "eggs", "coffee", "milk", "would", "prefer", "tea",
          "toast", "sweet", "or", "savory", "it's", "1", "2%", "café", "—", "a/b", "ok?")
_NAME_CHARS = "abcdefghijklmnopqrstuvwxyz0123456789_"


def _question(rng: random.Random) -> str:
    words = [rng.choice(_WORDS) for _ in range(rng.randint(1, 9))]
    return '"' + " ".join(words).capitalize() + rng.choice(("?", ".", "", "!")) + '"'


def _name(rng: random.Random) -> str:
    return rng.choice("abcdefghijklmnopqrstuvwxyz") + "".join(rng.choice(_NAME_CHARS)
                                                             for _ in range(rng.randint(0, 14)))


def _pool(kind: str, observed: Observed, level: str) -> list:
    if level == "typed":
        return sorted({"entity": observed.entities, "content": observed.contents,
                       "thing": observed.entities | observed.contents}[kind])
    return sorted(observed.entities | observed.contents)


def _fill(slot: Slot, form, index: GrammarIndex, observed: Observed, level: str, rng: random.Random) -> str:
    if slot.kind == "verb":
        verb = rng.choice([v for v in index.verbs if v not in form.exclude_verbs])
        return verb.capitalize() if rng.random() < 0.3 else verb
    if slot.kind == "query":
        return rng.choice(index.categories)
    if slot.kind == "question":
        return _question(rng)
    if slot.kind == "result" or level == "syntax":
        return _name(rng)
    return rng.choice(_pool(slot.kind, observed, level))


def sample(index: GrammarIndex, observed: Observed, rng: random.Random, level: str = "observed",
           actions: tuple | None = None) -> tuple[str, str, dict]:
    """One random (text, action id, slots) of the state's language; `actions` limits the action ids."""
    pool = [a for a in index.actions if actions is None or a.id in actions]
    if level == "typed" and not observed.contents:
        pool = [a for a in pool if "content" not in a.kinds]
    action = rng.choice(pool)
    form = rng.choice(action.forms)
    words, slots = [], {}
    for p in form.pieces:
        if isinstance(p, Lit):
            words.append(rng.choice((p.text, *p.alts)))
        else:
            slots[p.name] = _fill(p, form, index, observed, level, rng)
            words.append(slots[p.name])
    return " ".join(words), action.id, slots
