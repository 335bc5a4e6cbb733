"""How adaptbench was installed, for the hints that name what to install: an editable install of a
checkout (`pip install -e .`, the README's) or a wheel (`pip install adaptbench`).

    install_hint("models")   # "pip install torch==2.13.0 && pip install -e '.[models]'" in a checkout
                             # "pip install torch==2.13.0 && pip install 'adaptbench[models]'" from a wheel
"""

from __future__ import annotations

from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent
_CHECKOUT = _PACKAGE.parent.parent  # src/adaptbench -> the repository root, in a checkout
TORCH = "pip install torch==2.13.0"  # first: the CPU build from a CPU index (docs/llm.md), not PyPI's CUDA one
NEEDS_TORCH = ("models", "train")


def editable() -> bool:
    """Whether adaptbench runs from a checkout's source tree (src/adaptbench beside pyproject.toml)."""
    return _PACKAGE.parent.name == "src" and (_CHECKOUT / "pyproject.toml").is_file()


def install_hint(extra: str) -> str:
    """The command that installs `extra` the way adaptbench was installed (torch first where it needs it)."""
    torch = f"{TORCH} && " if extra in NEEDS_TORCH else ""
    if editable():
        return f"{torch}pip install -e '{_CHECKOUT}[{extra}]'"
    return f"{torch}pip install 'adaptbench[{extra}]'"
