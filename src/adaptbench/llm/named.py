"""Models shipped inside the package, named instead of given as a directory: `--model student` is the
base student that cooks (behaviour-cloned on the oracle's episodes of split 0's training personas:
`adapt model curve` built it and `adapt model student --init` continued it on new scenes, docs/training.md;
its `student.json` holds the provenance), at `adaptbench/checkpoints/student/`; `--model student-rdpo` is that student
after Reflection-DPO (`adapt train reproduce --base` on it, then `adapt model ship`; its `training.json` holds the
provenance and the evaluation), at `adaptbench/checkpoints/student-rdpo/`. A path that exists always wins over a
name."""

from __future__ import annotations

from pathlib import Path

NAMED = {"student": "checkpoints/student", "student-rdpo": "checkpoints/student-rdpo"}


def named_path(name: str) -> Path:
    """The directory of the shipped model `name` (KeyError for an unknown name)."""
    return Path(__file__).resolve().parent.parent / NAMED[name]


def resolve_model(model: str | None) -> str | None:
    """`model` itself when it is an existing path (or None), else the shipped model of that name, else
    `model` unchanged (the caller reports a missing directory)."""
    if model is None or Path(model).exists() or model not in NAMED:
        return model
    return str(named_path(model))
