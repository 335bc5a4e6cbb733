"""YAML loading that keeps the line and column of every node and rejects duplicate keys.

The loader returns plain Python data plus a `Positions` table mapping each node's path
(a tuple of keys and indices) to where it starts in the file, so later passes can point at
the exact spot of a problem.
"""

from __future__ import annotations

import math
import re
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

MAX_DEPTH = 64  # nesting of YAML collections, checked on the token stream before anything recursive runs
MAX_NODES = 100_000  # values in one document once aliases are expanded
MAX_INT = 2**53  # larger integers are not spec values (and lose precision in JSON)
_CONTROL = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\x7f]")
_OPEN = (yaml.BlockMappingStartToken, yaml.BlockSequenceStartToken, yaml.FlowMappingStartToken,
         yaml.FlowSequenceStartToken)
_CLOSE = (yaml.BlockEndToken, yaml.FlowMappingEndToken, yaml.FlowSequenceEndToken)
_STD = "tag:yaml.org,2002:"
_IMPLICIT = {_STD + t for t in ("str", "int", "float", "bool", "null", "map", "seq", "timestamp")}
_NAMES = {0: "NUL", 7: "bell", 8: "backspace", 0x1B: "escape", 0x7F: "delete"}


class _Reject(Exception):
    """A problem that stops reading the document (too deep, too big)."""

    def __init__(self, diag: Diagnostic):
        super().__init__(diag.message)
        self.diag = diag


def _diag(file: str, mark, code: str, message: str) -> Diagnostic:
    return Diagnostic(file, mark.line + 1, mark.column + 1, code, message)


def _prescan(text: str, file: str) -> list[Diagnostic]:
    """Control characters, explicit tags and nesting depth, found on the token stream (C scanner, no
    recursion) before the composer, which recurses in C, sees the text."""
    m = _CONTROL.search(text)
    if m:
        line = text.count("\n", 0, m.start()) + 1
        col = m.start() - (text.rfind("\n", 0, m.start()) + 1) + 1
        code = ord(m.group())
        name = _NAMES.get(code, "control character")
        return [Diagnostic(file, line, col, "S010", f"{name} (U+{code:04X}) in the file: spec files are plain "
                                                    f"UTF-8 text without control characters")]
    try:
        return _scan_tokens(text, file)
    except yaml.MarkedYAMLError as exc:  # a syntax error: the composer reports it (every token before it was
        return _too_deep(text, file, exc.problem_mark)  # checked), unless the scanner gave up on nesting first
    except yaml.YAMLError:
        return []


def _too_deep(text: str, file: str, mark) -> list[Diagnostic]:
    """S012 when the scanner stopped inside more than MAX_DEPTH open flow brackets: newer PyYAML scanners
    limit nesting themselves, before a `[`/`{` token reaches `_scan_tokens` (they are held back while a
    simple key may still follow), and their wording is theirs to change."""
    if mark is None:
        return []
    head = text[:mark.index]
    depth = head.count("[") + head.count("{") - head.count("]") - head.count("}")
    if depth <= MAX_DEPTH:
        return []
    return [_diag(file, mark, "S012", f"nesting too deep (more than {MAX_DEPTH} levels)")]


def _scan_tokens(text: str, file: str) -> list[Diagnostic]:
    depth = 0
    for tok in yaml.scan(text, Loader=_Loader):
        if isinstance(tok, yaml.TagToken):
            handle, suffix = tok.value
            return [_diag(file, tok.start_mark, "S011", f"YAML tag '{(handle or '')}{suffix}' is not supported "
                                                       f"(spec files hold plain values; remove the tag)")]
        if isinstance(tok, _OPEN):
            depth += 1
            if depth > MAX_DEPTH:
                return [_diag(file, tok.start_mark, "S012", f"nesting too deep (more than {MAX_DEPTH} levels)")]
        elif isinstance(tok, _CLOSE):
            depth -= 1
    return []


def _scalar(node, file: str):
    if node.tag == _STD + "merge":
        raise _Reject(_diag(file, node.start_mark, "S013", "merge keys (<<) are not supported; write the fields "
                                                           "out (or repeat them)"))
    if node.tag not in _IMPLICIT:
        raise _Reject(_diag(file, node.start_mark, "S011", f"YAML tag '{node.tag}' is not supported"))
    try:
        value = _CONSTRUCTOR.construct_object(node, deep=True)
    except (ValueError, OverflowError, yaml.YAMLError) as exc:
        raise _Reject(_diag(file, node.start_mark, "S014", f"number too large or unreadable value ({exc})")) from None
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > MAX_INT:
        raise _Reject(_diag(file, node.start_mark, "S014", f"number too large (more than {MAX_INT:,} in size)"))
    if isinstance(value, float) and not math.isfinite(value):
        raise _Reject(_diag(file, node.start_mark, "S014", f"not a finite number: {node.value}"))
    return value


class _Builder:
    """Plain data from a node graph, with positions, a node budget (aliases) and a depth bound."""

    def __init__(self, pos: Positions, diags: list):
        self.pos, self.diags, self.count = pos, diags, 0

    def build(self, node, path, depth: int = 0):
        self.count += 1
        if self.count > MAX_NODES or depth > MAX_DEPTH:
            what = (f"more than {MAX_NODES:,} values" if self.count > MAX_NODES
                    else f"nesting deeper than {MAX_DEPTH} levels")
            raise _Reject(_diag(self.pos.file, node.start_mark, "S015",
                                f"document too large after expanding aliases ({what}); "
                                f"aliases (*name) cannot repeat this much or refer to themselves"))
        self.pos.marks[path] = _mark(node)
        if isinstance(node, yaml.MappingNode):
            return self._mapping(node, path, depth)
        if isinstance(node, yaml.SequenceNode):
            if node.tag != _STD + "seq":
                raise _Reject(_diag(self.pos.file, node.start_mark, "S011", f"YAML tag '{node.tag}' is not supported"))
            return [self.build(child, path + (i,), depth + 1) for i, child in enumerate(node.value)]
        return _scalar(node, self.pos.file)

    def _mapping(self, node, path, depth: int) -> dict:
        if node.tag != _STD + "map":
            raise _Reject(_diag(self.pos.file, node.start_mark, "S011", f"YAML tag '{node.tag}' is not supported"))
        out = {}
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                raise _Reject(_diag(self.pos.file, key_node.start_mark, "S016",
                                    "a key must be a plain word or string, not a list or mapping"))
            key = _scalar(key_node, self.pos.file)
            if key in out:
                m = _mark(key_node)
                first = self.pos.marks[("<key>",) + path + (key,)]
                self.diags.append(Diagnostic(self.pos.file, m.line, m.col, "S001",
                                             f"duplicate key '{key}' (first defined at line {first.line})"))
                continue
            self.pos.marks[("<key>",) + path + (key,)] = _mark(key_node)
            out[key] = self.build(value_node, path + (key,), depth + 1)
        return out


def _unclosed_quote(text: str, exc) -> tuple | None:
    """(line, column, line of the error) of the quote that opened a value left unclosed, when that is what
    the syntax error `exc` comes from: the scanner stopped inside a quoted scalar, or the last token read
    before the error is a quoted scalar spanning lines (its closing quote is another value's opening one)."""
    if "quoted scalar" in (exc.context or "") and exc.context_mark is not None:
        m = exc.context_mark
        return m.line + 1, m.column + 1, (exc.problem_mark or m).line + 1
    err = exc.problem_mark or exc.context_mark
    if err is None:
        return None
    quoted = None
    try:
        for token in yaml.scan(text, Loader=_Loader):
            if token.start_mark.line > err.line:
                break
            if isinstance(token, yaml.ScalarToken) and token.style in ('"', "'"):
                quoted = token
    except yaml.YAMLError:
        pass
    if quoted is not None and quoted.start_mark.line < quoted.end_mark.line and err.line - quoted.end_mark.line <= 1:
        return quoted.start_mark.line + 1, quoted.start_mark.column + 1, err.line + 1
    return None


def load_yaml(text: str, file: str) -> tuple[LoadedDoc | None, list[Diagnostic]]:
    """Parse one YAML document keeping positions; syntax errors and hostile input become diagnostics."""
    diags: list[Diagnostic] = []
    pos = Positions(file)
    try:
        bad = _prescan(text, file)
        if bad:
            return None, bad
        node = yaml.compose(text, Loader=_Loader)
        if node is None:
            return LoadedDoc(file, {}, pos), diags
        data = _Builder(pos, diags).build(node, ())
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line, col = (mark.line + 1, mark.column + 1) if mark else (1, 1)
        opened = _unclosed_quote(text, exc)
        if opened:
            return None, [Diagnostic(file, *opened[:2], "S000", f"YAML syntax error: the quoted value opened here is "
                                     f"not closed (it runs on to line {opened[2]}, where parsing fails: close it "
                                     "on this line)")]
        from .yamlhints import hint

        why = hint(f"{exc.context or ''} {exc.problem or ''}", text, line, col)
        return None, [Diagnostic(file, line, col, "S000", f"YAML syntax error: {exc.problem}" + (f" ({why})" if why else ""))]
    except yaml.YAMLError as exc:  # reader errors (unprintable characters) carry no mark
        return None, [Diagnostic(file, 1, 1, "S000", f"YAML error: {exc}")]
    except _Reject as exc:
        return None, [exc.diag]
    return LoadedDoc(file, data, pos), diags
