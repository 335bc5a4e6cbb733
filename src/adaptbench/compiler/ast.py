"""The rule language's AST: frozen dataclasses that keep the position they were parsed from.

Positions are 1-based line/column in the *spec file* once the compiler has offset them.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace


@dataclass(frozen=True)
class Node:
    """Base of every AST node."""

    line: int
    col: int


# ---- class expressions: which items/entities a name matches ----
@dataclass(frozen=True)
class ClsName(Node):
    """A class name: category, tag, entity, room or substance id (or a style / verb group)."""

    name: str


@dataclass(frozen=True)
class ClsAny(Node):
    """`a | b`: matches either."""

    items: tuple


@dataclass(frozen=True)
class ClsAll(Node):
    """`a & b`: matches both."""

    items: tuple


@dataclass(frozen=True)
class ClsNeg(Node):
    """`!a`: does not match."""

    item: object


@dataclass(frozen=True)
class ClsMod(Node):
    """`heated a` / `chopped a`: an ingredient that was heated / cut on its way into the dish."""

    mod: str
    item: object


# ---- boolean expressions ----
@dataclass(frozen=True)
class Const(Node):
    """`true` or `false`."""

    value: bool


@dataclass(frozen=True)
class AnyOf(Node):
    """`a or b`."""

    items: tuple


@dataclass(frozen=True)
class AllOf(Node):
    """`a and b`."""

    items: tuple


@dataclass(frozen=True)
class Not(Node):
    """`not a`."""

    item: object


@dataclass(frozen=True)
class IfElse(Node):
    """`if c then a else b`."""

    cond: object
    then: object
    other: object


@dataclass(frozen=True)
class Pred(Node):
    """An atomic predicate: `op` names it (has, has_no, served_at, count, ...).

    `subject` is the subject word (it, meal, sides, a component/group, or an action slot),
    `args` holds class expressions, a second subject, comparison and number, or a name.
    """

    op: str
    subject: str | None
    args: tuple


@dataclass(frozen=True)
class Each(Node):
    """`each S [with X] (expr)`: expr holds for every dish of subject S (that has an ingredient matching
    X), with `it` bound to that dish alone; true when there is none."""

    subject: str
    cls: object | None
    expr: object


@dataclass(frozen=True)
class Scope(Node):
    """`for targets [if cond]:` of a preference rule."""

    targets: tuple
    cond: object | None


@dataclass(frozen=True)
class Rule(Node):
    """A parsed rule: optional scope, expression, its source text and file."""

    scope: Scope | None
    expr: object
    source: str = ""
    file: str = ""


_TYPES = {cls.__name__: cls for cls in (ClsName, ClsAny, ClsAll, ClsNeg, ClsMod, Const, AnyOf, AllOf,
                                        Not, IfElse, Pred, Each, Scope, Rule)}


def to_data(node):
    """Serialise an AST (or any value inside one) to JSON-compatible data."""
    if isinstance(node, Node):
        out = {"_t": type(node).__name__}
        for f in fields(node):
            out[f.name] = to_data(getattr(node, f.name))
        return out
    if isinstance(node, tuple | list):
        return [to_data(x) for x in node]
    return node


def from_data(data):
    """Inverse of `to_data`."""
    if isinstance(data, dict) and "_t" in data:
        cls = _TYPES[data["_t"]]
        kwargs = {k: from_data(v) for k, v in data.items() if k != "_t"}
        return cls(**kwargs)
    if isinstance(data, list):
        return tuple(from_data(x) for x in data)
    return data


def walk(node):
    """Yield every AST node under `node`, depth first."""
    if isinstance(node, Node):
        yield node
        for f in fields(node):
            yield from walk(getattr(node, f.name))
    elif isinstance(node, tuple):
        for x in node:
            yield from walk(x)


def shift(node, line_offset: int, col_offset: int):
    """Move positions from rule-text coordinates into file coordinates.

    Nodes on the rule's first line get `col_offset` added; every node gets `line_offset`.
    """
    if isinstance(node, tuple):
        return tuple(shift(x, line_offset, col_offset) for x in node)
    if not isinstance(node, Node):
        return node
    changes = {f.name: shift(getattr(node, f.name), line_offset, col_offset)
               for f in fields(node) if f.name not in ("line", "col")}
    col = node.col + (col_offset if node.line == 1 else 0)
    return replace(node, line=node.line + line_offset, col=col, **changes)


def render_cls(cls) -> str:
    """Class expression back to text."""
    if isinstance(cls, ClsName):
        return cls.name
    if isinstance(cls, ClsAny):
        return " | ".join(render_cls(x) for x in cls.items)
    if isinstance(cls, ClsAll):
        return " & ".join(_paren(x) for x in cls.items)
    if isinstance(cls, ClsNeg):
        return "!" + _paren(cls.item)
    if isinstance(cls, ClsMod):
        return f"{cls.mod} {_paren(cls.item)}"
    return str(cls)


def _paren(cls) -> str:
    text = render_cls(cls)
    return f"({text})" if isinstance(cls, ClsAny | ClsAll) else text
