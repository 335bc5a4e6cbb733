"""Argument types shared by the `adapt` commands: bad values are usage errors with a message."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

MAX_SEED = 2**63 - 1


def seed(text: str) -> int:
    """A scene seed: a whole number from 0."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a seed (a whole number >= 0)") from None
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"seed {text} is out of range (0 to {MAX_SEED})")
    return value


def positive(text: str) -> int:
    """A whole number >= 1 (a step limit, a count)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text} must be at least 1")
    return value


def temperature(text: str) -> float:
    """A sampling temperature: a finite number >= 0 (0: greedy)."""
    import math

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a temperature (a number >= 0; 0 is greedy)") from None
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"temperature {text} must be a finite number >= 0 (0 is greedy)")
    return value


def read_lines(path: str) -> list:
    """The non-blank, non-comment lines of a text file ('-' for stdin). Exits 2 with a message when the
    file cannot be read or is not UTF-8 text."""
    try:
        text = sys.stdin.read() if path == "-" else Path(path).read_text(encoding="utf-8")
    except IsADirectoryError:
        _fail(f"{path} is a directory, not a file of actions")
    except OSError as exc:
        _fail(f"cannot read {path}: {exc.strerror}")
    except UnicodeDecodeError as exc:
        _fail(f"{path} is not UTF-8 text (byte {exc.start}: {exc.reason})")
    return [ln.strip() for ln in text.splitlines() if ln.strip() and not ln.strip().startswith("#")]


def _fail(message: str):
    print(f"adapt: {message}", file=sys.stderr)
    raise SystemExit(2)


def spec_dir(text: str) -> str:
    """A spec directory. `spec` where no such directory exists (an installed wheel run from any directory
    but a checkout's root, where the README's `adapt validate spec` points) is the paper's spec shipped
    with adaptbench, said on stderr; any other path is taken as given."""
    if Path(text).as_posix().rstrip("/") != "spec" or Path(text).exists():
        return text
    from ..paper import shipped_spec

    print(f"adapt: note: no directory '{text}' here; using the paper's spec shipped with adaptbench "
          f"({shipped_spec()})", file=sys.stderr)
    return str(shipped_spec())
