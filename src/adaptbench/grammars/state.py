"""Per-state grammars, updated incrementally: the base of each (task, level, variant) is emitted once
and cached in a `GrammarCache`; a `StateGrammar` keeps the sorted, quoted names of its entity
terminals and, when the agent observes more, inserts the new names and re-emits only the terminals
that changed."""

from __future__ import annotations

import bisect

from .emit import Base, Observed, build_base, quote, usable_actions
from .index import GrammarIndex


class GrammarCache:
    """The static bases of one domain's grammars, by (task, level, variant, question set); built on first use."""

    def __init__(self, index: GrammarIndex, titles: dict | None = None):
        self.index = index
        self.titles = titles or {}  # task id -> header title
        self._bases: dict = {}

    def base(self, task: str | None, level: str = "observed", variant: str = "default",
             questions: str = "free") -> Base:
        """The cached static part for a task, level, variant and question set (`free` or `bank`)."""
        key = (task, level, variant, questions)
        hit = self._bases.get(key)
        if hit is None:
            hit = self._bases[key] = build_base(self.index, level, variant, self.titles.get(task, ""), questions)
        return hit

    def state(self, task: str | None, observed: Observed, level: str = "observed",
              variant: str = "default", questions: str = "free") -> StateGrammar:
        """A grammar for a state, ready to be updated as the agent observes more."""
        return StateGrammar(self.base(task, level, variant, questions), observed)


class _Terminal:
    """One entity terminal: its names reverse-sorted (an id before its prefixes), their quoted
    forms in the same order, and its emitted line."""

    __slots__ = ("name", "names", "keys", "quoted", "line")

    def __init__(self, name: str, names):
        self.name = name
        self.names = set(names)
        self.keys = sorted(self.names, reverse=True)
        self.quoted = [quote(n) for n in self.keys]
        self.line = self._emit()

    def _emit(self) -> str:
        return f"{self.name}: " + " | ".join(self.quoted)

    def add(self, new) -> None:
        """Insert new names in order and re-emit the line."""
        for n in new:
            self.names.add(n)
            i = bisect.bisect_left(self.keys, _Rev(n), key=_Rev)
            self.keys.insert(i, n)
            self.quoted.insert(i, quote(n))
        self.line = self._emit()


class _Rev(str):
    """A string that sorts in reverse, for bisect over a reverse-sorted list."""

    __slots__ = ()

    def __lt__(self, other):
        return str.__gt__(self, other)


class StateGrammar:
    """The grammar of one state; `update` re-emits only what the new observations changed."""

    def __init__(self, base: Base, observed: Observed):
        self.base = base
        self._head = ""
        self._terminals: dict = {}
        self._set(observed, rebuild=True)

    def _wanted(self, observed: Observed) -> dict:
        if self.base.level == "syntax" or not any(k & {"entity", "content", "thing"}
                                                  for k in self.base.kinds.values()):
            return {}
        if self.base.level == "observed":
            return {"OBSERVED": observed.entities | observed.contents}
        out = {"ENTITY": observed.entities}
        if observed.contents:
            out["CONTENT"] = observed.contents
        return out

    def _set(self, observed: Observed, rebuild: bool = False) -> None:
        wanted = self._wanted(observed)
        shape_changed = set(wanted) != set(self._terminals)
        for name, names in wanted.items():
            term = self._terminals.get(name)
            if term is None or rebuild or not term.names <= names:
                self._terminals[name] = _Terminal(name, names)
            elif len(names) != len(term.names):
                term.add(names - term.names)
        for name in set(self._terminals) - set(wanted):
            del self._terminals[name]
        if rebuild or shape_changed:
            self._head = self._emit_head()
        self.observed = observed

    def _emit_head(self) -> str:
        b = self.base
        static = b.static
        if b.level == "typed" and "CONTENT" not in self._terminals:
            static = static.replace("?thing: ENTITY | CONTENT", "?thing: ENTITY")
        ids = usable_actions(b, self._terminals)
        parts = [b.header, "start: action", "action: " + " | ".join(ids), *(b.rules[a] for a in ids), static]
        return "\n".join(p for p in parts if p) + "\n"

    def update(self, observed: Observed) -> str:
        """Move to a new state (usually a superset of the last one) and return its grammar text."""
        self._set(observed)
        return self.text

    @property
    def text(self) -> str:
        """The Lark text of the current state."""
        return self._head + "".join(t.line + "\n" for t in sorted(self._terminals.values(), key=_name))


def _name(t: _Terminal) -> str:
    return t.name
