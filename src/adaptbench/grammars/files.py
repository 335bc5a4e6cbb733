"""The committed grammars under `grammars/`: the domain grammar (typed, every entity and substance the
domain declares: the upper bound of every state), the syntax-level grammar, and one per task (the
observed-level grammar of the task's first state: the layout and its contents). `build` writes them,
`check` lists the files that differ from a fresh emission."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from .emit import Observed
from .index import GrammarIndex
from .state import GrammarCache

if TYPE_CHECKING:  # the grammars read a domain's forms; they import nothing of the compiler
    from ..compiler.model import CompiledDomain


def expected_files(domain: CompiledDomain, index: GrammarIndex) -> dict:
    """Relative path -> text of every committed grammar, as the spec gives them now."""
    cache = GrammarCache(index, {t.id: f"task {t.id}: {t.text}" for t in domain.tasks})
    everything = Observed(frozenset(index.entities), frozenset(index.substances))
    first = Observed(frozenset(index.layout), frozenset(index.layout_contents))
    out = {"domain.lark": cache.state(None, everything, "typed").text,
           "syntax.lark": cache.state(None, first, "syntax").text}
    for t in domain.tasks:
        out[f"tasks/{t.id}.lark"] = cache.state(t.id, first, "observed").text
    return out


def build(root: Path, files: dict) -> list:
    """Write the grammars under `root` (removing stale *.lark files); returns the paths written."""
    for old in root.rglob("*.lark"):
        if str(old.relative_to(root)) not in files:
            old.unlink()
    written = []
    for rel, text in sorted(files.items()):
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        written.append(path)
    return written


def drift(root: Path, files: dict) -> list:
    """(path, problem) for every committed grammar that is missing, differs, or is not generated."""
    out = []
    for rel, text in sorted(files.items()):
        path = root / rel
        if not path.exists():
            out.append((path, "missing"))
        elif path.read_text(encoding="utf-8") != text:
            out.append((path, "differs from what spec/ gives"))
    if root.exists():
        out += [(p, "not generated from spec/ (stale)") for p in sorted(root.rglob("*.lark"))
                if str(p.relative_to(root)) not in files]
    return out
