"""The runtime's per-domain tables, derived once per `CompiledDomain` and passed explicitly: the
grammar index, the action parser (structural grammar, cached by text), actions by id and their
compiled preconditions.

    index = runtime_index(domain)        # built on first use, kept with the domain
    env = Env(domain, "eggs", index=index)
"""

from __future__ import annotations

from dataclasses import dataclass

from ..compiler.model import CompiledDomain
from ..grammars.index import GrammarIndex, build_index
from ..grammars.parser import ActionParser
from .actions import compile_check


@dataclass(frozen=True, eq=False)
class RuntimeIndex:
    """What the simulator derives from a domain, once."""

    domain: CompiledDomain
    grammar: GrammarIndex
    parser: ActionParser
    checks: dict  # action id -> ((check, failure message), ...)
    substances_by_category: dict  # category -> (substance id, ...) in spec order


def build_runtime_index(domain: CompiledDomain) -> RuntimeIndex:
    """Derive the runtime tables of a domain (prefer `runtime_index`, which builds them once)."""
    grammar = domain.derived("grammars.index", build_index)
    checks = {a.id: tuple((compile_check(p.check, dict(a.slots)), p.fail) for p in a.preconditions)
              for a in domain.actions}
    by_category: dict = {}
    for s in domain.substances:
        by_category.setdefault(s.category, []).append(s.id)
    return RuntimeIndex(domain, grammar, ActionParser(grammar), checks,
                        {c: tuple(ids) for c, ids in by_category.items()})


def runtime_index(domain: CompiledDomain) -> RuntimeIndex:
    """The runtime index of a domain, built on first use and kept with the domain."""
    return domain.derived("runtime.index", build_runtime_index)
