"""The runtime's per-domain index, derived once per `CompiledDomain` and passed explicitly: the
grammar index, the action parser (structural grammar, cached by text), actions by id and their
compiled preconditions, and the domain's light tables (`runtime.tables`: rooms, search keys, scenes,
world templates, compiled rules — the bounded caches).

    index = runtime_index(domain)        # built on first use, kept with the domain
    env = Env(domain, "eggs", index=index)
"""

from __future__ import annotations

from dataclasses import dataclass

from ..compiler.model import CompiledDomain
from ..grammars.index import GrammarIndex, build_index
from ..grammars.parser import ActionParser
from .actions import compile_check
from .tables import DomainTables, domain_tables


@dataclass(frozen=True, eq=False)
class RuntimeIndex:
    """What the simulator derives from a domain, once."""

    domain: CompiledDomain
    grammar: GrammarIndex
    parser: ActionParser
    checks: dict  # action id -> ((check, failure message), ...)
    tables: DomainTables  # the light tables and bounded caches (rooms, search, scenes, compiled rules)


def build_runtime_index(domain: CompiledDomain) -> RuntimeIndex:
    """Derive the runtime tables of a domain (prefer `runtime_index`, which builds them once)."""
    grammar = domain.derived("grammars.index", build_index)
    checks = {a.id: tuple((compile_check(p.check, dict(a.slots)), p.fail) for p in a.preconditions)
              for a in domain.actions}
    return RuntimeIndex(domain, grammar, ActionParser(grammar), checks, domain_tables(domain))


def runtime_index(domain: CompiledDomain) -> RuntimeIndex:
    """The runtime index of a domain, built on first use and kept with the domain."""
    return domain.derived("runtime.index", build_runtime_index)
