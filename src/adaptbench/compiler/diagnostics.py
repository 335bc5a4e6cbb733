"""Diagnostics: author mistakes reported as `path:line:col: severity[CODE]: message`."""

from __future__ import annotations

import difflib
import json
from collections.abc import Iterable
from dataclasses import asdict, dataclass

from ..errors import AdaptError


@dataclass(frozen=True, order=True)
class Diagnostic:
    """One problem in a spec file, with the position it points at."""

    path: str
    line: int
    col: int
    code: str
    message: str
    severity: str = "error"

    def render(self) -> str:
        """Format as `path:line:col: severity[CODE]: message`."""
        return f"{self.path}:{self.line}:{self.col}: {self.severity}[{self.code}]: {self.message}"


class SpecError(AdaptError, ValueError):
    """Raised when a spec does not compile; carries every diagnostic found."""

    def __init__(self, diagnostics: list[Diagnostic]):
        self.diagnostics = sorted(diagnostics)
        super().__init__("\n".join(d.render() for d in self.diagnostics))


def did_you_mean(word: str, candidates: Iterable[str], n: int = 1) -> str:
    """Return ' (did you mean 'x'?)' for the closest candidate, or ''."""
    close = difflib.get_close_matches(word, list(candidates), n=n, cutoff=0.6)
    if not close:
        return ""
    return " (did you mean " + " or ".join(f"'{c}'" for c in close) + "?)"


def render_all(diagnostics: Iterable[Diagnostic], fmt: str = "text") -> str:
    """Render diagnostics as text lines or as a JSON array."""
    diags = sorted(diagnostics)
    if fmt == "json":
        return json.dumps([asdict(d) for d in diags], indent=2)
    return "\n".join(d.render() for d in diags)
