"""Hints for YAML syntax errors: the parser says what it found, the hint says what authors usually did.

The usual causes in spec files: a tab used for indentation, a line indented more or less than its
neighbours, and an unquoted `: ` inside a value (a rule such as `rule: for eggs: it has milk`).
"""

from __future__ import annotations

import re

_KEY = re.compile(r"^\s*(?:-\s+)?[A-Za-z0-9_\"' ]+:\s")

INDENT = ("check the indentation of this line against the lines above: the fields of one item, and the "
          "items of one list, must start in the same column")
TABS = "YAML does not allow tabs for indentation: indent with spaces"
COLON = ("a value that contains ': ' must be quoted; write the whole value in double quotes, "
         'e.g. rule: "for eggs: it has milk"')
QUOTE = "a quoted value is not closed: check the quotes on this line and the lines above"
BRACKET = "a [list] or {mapping} written on one line is not closed, or an item in it needs quotes"


def hint(problem: str | None, text: str, line: int, col: int) -> str:
    """A sentence on the likely cause of a YAML syntax error at 1-based `line`:`col` of `text`, or ''."""
    problem = problem or ""
    lines = text.splitlines()
    here = lines[line - 1] if 0 < line <= len(lines) else ""
    if "tab" in problem or "\t" in here[: len(here) - len(here.lstrip())] or (
            "cannot start any token" in problem and here[col - 1: col] == "\t"):
        return TABS
    opened = _open_quote(lines, line)
    if opened:
        return f"the quoted value opened on line {opened} is not closed"
    if "mapping values are not allowed" in problem:
        before = here[: col - 1]
        return COLON if _KEY.match(before) else INDENT
    if "quoted scalar" in problem or "end of stream" in problem and here.count('"') % 2:
        return QUOTE
    if "expected ',' or ']'" in problem or "expected ',' or '}'" in problem:
        item = here[max(here.rfind(",", 0, col - 1), here.rfind("{", 0, col - 1)) + 1: col - 1]
        return COLON if here[col - 1: col] == ":" and ": " in item else BRACKET
    if any(k in problem for k in ("expected key", "'-' indicator", "block end", "expected ':'")):
        return INDENT
    return ""


def _open_quote(lines: list, line: int) -> int:
    """The 1-based line, among the few before `line`, where a double-quoted value starts but does not end."""
    for n in range(line - 1, max(0, line - 6), -1):
        text = lines[n - 1] if n <= len(lines) else ""
        if text.replace('\\"', "").count('"') % 2:
            return n
    return 0
