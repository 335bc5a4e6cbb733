"""YAML loading that keeps the line and column of every node and rejects duplicate keys.

The loader returns plain Python data plus a `Positions` table mapping each node's path
(a tuple of keys and indices) to where it starts in the file, so later passes can point at
the exact spot of a problem.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import yaml

try:  # libyaml is ~10x faster and keeps marks
    from yaml import CSafeLoader as _Loader
except ImportError:  # pragma: no cover
    from yaml import SafeLoader as _Loader

from .diagnostics import Diagnostic

Path = tuple


@dataclass(frozen=True)
class Mark:
    """1-based line and column of a node, and the scalar style (None, '"', "'", '|', '>')."""

    line: int
    col: int
    style: str | None = None


@dataclass
class Positions:
    """Where every node of one YAML document starts."""

    file: str
    marks: dict = field(default_factory=dict)

    def at(self, path: Path) -> Mark:
        """The mark of `path`, or of its nearest ancestor that has one."""
        while path not in self.marks and path:
            path = path[:-1]
        return self.marks.get(path, Mark(1, 1))

    def key(self, path: Path) -> Mark:
        """The mark of the mapping key that introduces `path` (falls back to the value)."""
        return self.marks.get(("<key>",) + tuple(path)) or self.at(path)


@dataclass
class LoadedDoc:
    """A parsed YAML file: its data and node positions."""

    file: str
    data: object
    pos: Positions


def _mark(node) -> Mark:
    return Mark(node.start_mark.line + 1, node.start_mark.column + 1, getattr(node, "style", None))


_CONSTRUCTOR = yaml.constructor.SafeConstructor()


def _scalar(node):
    return _CONSTRUCTOR.construct_object(node, deep=True)


def _build(node, path, pos: Positions, diags: list):
    pos.marks[path] = _mark(node)
    if isinstance(node, yaml.MappingNode):
        out = {}
        for key_node, value_node in node.value:
            key = _scalar(key_node)
            if key in out:
                m = _mark(key_node)
                first = pos.marks[("<key>",) + path + (key,)]
                diags.append(Diagnostic(pos.file, m.line, m.col, "S001",
                                        f"duplicate key '{key}' (first defined at line {first.line})"))
                continue
            pos.marks[("<key>",) + path + (key,)] = _mark(key_node)
            out[key] = _build(value_node, path + (key,), pos, diags)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_build(child, path + (i,), pos, diags) for i, child in enumerate(node.value)]
    return _scalar(node)


def load_yaml(text: str, file: str) -> tuple[LoadedDoc | None, list[Diagnostic]]:
    """Parse one YAML document keeping positions; syntax errors become diagnostics."""
    diags: list[Diagnostic] = []
    pos = Positions(file)
    try:
        node = yaml.compose(text, Loader=_Loader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line, col = (mark.line + 1, mark.column + 1) if mark else (1, 1)
        return None, [Diagnostic(file, line, col, "S000", f"YAML syntax error: {exc.problem}")]
    if node is None:
        return LoadedDoc(file, {}, pos), diags
    data = _build(node, (), pos, diags)
    return LoadedDoc(file, data, pos), diags
