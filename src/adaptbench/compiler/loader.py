"""Find spec files, parse them with positions, and validate them against the JSON Schemas."""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

from .diagnostics import Diagnostic, did_you_mean

# yamlpos (PyYAML) is imported where a file is read: hashing the spec to find a cached domain needs only
# spec_files.
if TYPE_CHECKING:
    from .yamlpos import LoadedDoc

KINDS = {"objects": "objects", "actions": "actions", "tasks": "tasks", "personas": "persona"}
ROOT_FILES = {"engine.yaml": "engine", "splits.yaml": "splits"}  # single files at the top of a spec dir
SCHEMA_KINDS = tuple(sorted(set(KINDS.values()) | set(ROOT_FILES.values())))


def spec_files(spec_dirs: list[Path]) -> list[tuple[str, Path]]:
    """(kind, path) for every YAML file of each spec dir (its top-level files, then its kind folders, sorted)."""
    out = []
    for root in spec_dirs:
        for name, kind in ROOT_FILES.items():
            if (Path(root) / name).is_file():
                out.append((kind, Path(root) / name))
        for folder, kind in KINDS.items():
            for path in sorted((Path(root) / folder).glob("*.y*ml")):
                out.append((kind, path))
    return out


@cache
def schema(kind: str) -> dict:
    """The JSON Schema for one kind of spec file (shipped as package data)."""
    from importlib import resources

    text = resources.files("adaptbench.compiler").joinpath(f"schemas/{kind}.schema.json").read_text()
    return json.loads(text)


def load_file(path: Path, display: str) -> tuple[LoadedDoc | None, list[Diagnostic]]:
    """Read and parse one YAML file."""
    from .yamlpos import load_yaml

    try:
        data = path.read_bytes()
    except OSError as exc:
        return None, [Diagnostic(display, 1, 1, "S002", f"cannot read file: {exc.strerror or exc}")]
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        col = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        return None, [Diagnostic(display, line, col, "S002", f"not UTF-8 text: byte 0x{data[exc.start]:02x} cannot be "
                                                             f"decoded (save the file as UTF-8)")]
    return load_yaml(text, display)


@cache
def _validator(kind: str):
    import jsonschema  # imported lazily: the cached path never needs it

    base = jsonschema.validators.validator_for(schema(kind))
    return jsonschema.validators.extend(base, {"pattern": _full_pattern})(schema(kind))


def _full_pattern(validator, pattern: str, instance, schema_):
    """`pattern` where `$` means the end of the string: Python's `$` also matches before a final newline,
    so 'pan_0\\n' would pass `^[a-z0-9_]+$`."""
    import re

    from jsonschema.exceptions import ValidationError

    if not validator.is_type(instance, "string"):
        return
    anchored = pattern[:-1] + r"\Z" if pattern.endswith("$") and not pattern.endswith(r"\$") else pattern
    if not re.search(anchored, instance):
        yield ValidationError(f"{instance!r} does not match {pattern!r}")


def validate_schema(doc: LoadedDoc, kind: str) -> list[Diagnostic]:
    """Schema diagnostics for one document, each pointing at the offending node."""
    if not isinstance(doc.data, dict):
        return [Diagnostic(doc.file, 1, 1, "S103", "the file must be a mapping at the top level")]
    errors = sorted(_validator(kind).iter_errors(doc.data), key=lambda e: list(map(str, e.absolute_path)))
    return [d for e in errors for d in _explain(doc, e)]


def _explain(doc: LoadedDoc, err) -> list[Diagnostic]:
    path = tuple(err.absolute_path)
    if err.validator == "additionalProperties":
        allowed = list(err.schema.get("properties", {}))
        extra = [k for k in err.instance if k not in allowed]
        out = []
        for key in extra:
            m = doc.pos.key(path + (key,))
            hint = did_you_mean(str(key), allowed) or f" (allowed: {', '.join(allowed)})"
            out.append(Diagnostic(doc.file, m.line, m.col, "S101", f"unknown field '{key}'{hint}"))
        return out
    m = doc.pos.at(path)
    if err.validator == "required":
        missing = err.message.split("'")[1] if "'" in err.message else err.message
        where = f" in {_describe(path)}" if path else ""
        return [Diagnostic(doc.file, m.line, m.col, "S102", f"missing required field '{missing}'{where}")]
    if err.validator == "type":
        want = err.validator_value if isinstance(err.validator_value, str) else " or ".join(err.validator_value)
        return [Diagnostic(doc.file, m.line, m.col, "S103",
                           f"{_describe(path)} should be {_article(want)}, not {_typename(err.instance)}")]
    if err.validator == "pattern":
        return [Diagnostic(doc.file, m.line, m.col, "S104",
                           f"{_describe(path)} '{err.instance}' must be snake_case (lowercase letters, digits, _)")]
    if err.validator == "enum":
        hint = did_you_mean(str(err.instance), map(str, err.validator_value))
        return [Diagnostic(doc.file, m.line, m.col, "S105",
                           f"{_describe(path)} '{err.instance}' is not one of {', '.join(map(str, err.validator_value))}{hint}")]
    return [Diagnostic(doc.file, m.line, m.col, "S100", f"{_describe(path)}: {err.message}")]


def _describe(path) -> str:
    if not path:
        return "the file"
    named = [str(p) for p in path if not isinstance(p, int)]
    return f"'{named[-1]}'" if named else f"item {path[-1]}"


def _article(word: str) -> str:
    return ("an " if word[0] in "aeiou" else "a ") + word


def _typename(value) -> str:
    return {dict: "a mapping", list: "a list", str: "a string", int: "an integer", float: "a number",
            bool: "a boolean", type(None): "empty"}.get(type(value), type(value).__name__)
