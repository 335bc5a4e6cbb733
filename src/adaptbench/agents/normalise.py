"""Agent-side clean-up of model output before it is sent to the simulator: the simulator reads the
action language exactly as the grammar defines it, so whoever feeds model text calls `normalise`."""

from __future__ import annotations

import re

_PREFIX = re.compile(r"^\s*action\s*:\s*", re.IGNORECASE)


def normalise(text: str) -> str:
    """One action line from model text: the first non-empty line, an "Action:" prefix dropped, runs of
    whitespace made single spaces, trailing dots dropped (not inside a closing quote)."""
    line = next((ln for ln in text.splitlines() if ln.strip()), "")
    line = " ".join(_PREFIX.sub("", line).split())
    return line if line.endswith('"') else line.rstrip(".").rstrip()
