"""Parsing action text with a generated grammar (python-lark, Earley): the result is the action id
and its slot strings, the same shape the runtime's matcher returns."""

from __future__ import annotations

from dataclasses import dataclass

from lark import Lark, Token, Tree
from lark.exceptions import LarkError

from .index import GrammarIndex


@dataclass(frozen=True)
class Parsed:
    """A parsed action: its id and slot values by name."""

    action: str
    slots: tuple  # ((slot name, text), ...) in form order

    @property
    def args(self) -> dict:
        """Slot values by name."""
        return dict(self.slots)


def lark_parser(text: str) -> Lark:
    """A lark parser for a generated grammar."""
    return Lark(text, start="start", parser="earley", lexer="dynamic")


def _value(node) -> str:
    if isinstance(node, Token):
        return str(node)
    return "".join(_value(c) for c in node.children)


def parse(parser: Lark, index: GrammarIndex, text: str) -> Parsed | None:
    """The action `text` reads as under `parser`, or None when the grammar rejects it."""
    try:
        tree = parser.parse(text)
    except LarkError:
        return None
    node = tree.children[0].children[0]  # start -> action -> <action id>
    assert isinstance(node, Tree)
    names = {a.id: a.slots for a in index.actions}[str(node.data)]
    return Parsed(str(node.data), tuple(zip(names, (_value(c) for c in node.children), strict=True)))
