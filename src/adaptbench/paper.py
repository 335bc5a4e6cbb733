"""The paper's spec, shipped inside the package: the one default every command and `load_domain` use.

In a checkout (an editable install) it is the repository's `spec/` (authors edit it there) with its
`grammars/`; in an installed wheel, the copies built into `adaptbench/data/` (setup.py copies the two
folders at build time: the repository keeps one copy). `$ADAPT_SPEC` overrides the spec directory.

    load_domain(default_spec())       # what load_domain() does with no argument
    export_spec("myspec")             # `adapt spec export myspec`: a copy to start a new domain from
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

SPEC_ENV = "ADAPT_SPEC"
_PACKAGE = Path(__file__).resolve().parent
_CHECKOUT = _PACKAGE.parent.parent  # src/adaptbench -> the repository root, in a checkout


def _root() -> Path:
    if (_CHECKOUT / "spec").is_dir() and (_CHECKOUT / "pyproject.toml").is_file():
        return _CHECKOUT
    return _PACKAGE / "data"


def shipped_spec() -> Path:
    """The paper's spec directory as installed (the checkout's `spec/`, or the packaged copy)."""
    return _root() / "spec"


def default_spec() -> str:
    """The spec directory commands use by default: `$ADAPT_SPEC` when set, else the paper's spec."""
    return os.environ.get(SPEC_ENV) or str(shipped_spec())


def default_grammars() -> str:
    """The committed grammars of the paper's spec (the checkout's `grammars/`, or the packaged copy)."""
    return str(_root() / "grammars")


def is_packaged(path) -> bool:
    """Whether `path` lies inside the installed package's data (read-only: export it to edit it)."""
    try:
        Path(path).resolve().relative_to(_PACKAGE / "data")
        return True
    except ValueError:
        return False


def export_spec(dest) -> list:
    """Copy the paper's spec into `dest` (which must not exist, or be empty); returns the files written.
    FileExistsError when `dest` holds anything."""
    dest = Path(dest)
    if dest.exists() and (not dest.is_dir() or any(dest.iterdir())):
        raise FileExistsError(f"{dest} exists and is not an empty directory")
    src = shipped_spec()
    shutil.copytree(src, dest, dirs_exist_ok=True, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    return sorted(p for p in dest.rglob("*") if p.is_file())
