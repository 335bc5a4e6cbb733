"""Parse rule-language text into the AST (lark, LALR, grammar shipped as package data)."""

from __future__ import annotations

from functools import lru_cache
from importlib import resources

from lark import Lark, Token, Transformer, v_args
from lark.exceptions import UnexpectedCharacters, UnexpectedEOF, UnexpectedInput, UnexpectedToken

from ..errors import AdaptError
from . import ast as A


@lru_cache(maxsize=1)
def parser() -> Lark:
    """The LALR parser for the rule language (built once per process; lark keeps its tables in the compiled-domain
    cache directory, checked against the grammar's hash, which saves a third of a cold `adapt validate`)."""
    import hashlib

    from . import cache_dir

    text = resources.files("adaptbench.compiler").joinpath("rules.lark").read_text()
    tables = cache_dir() / f"rules-lalr-{hashlib.sha256(text.encode()).hexdigest()[:16]}.lark"
    try:
        tables.parent.mkdir(parents=True, exist_ok=True)
        cache = str(tables)
    except OSError:  # an unwritable cache only costs time
        cache = False
    return Lark(text, parser="lalr", propagate_positions=True, maybe_placeholders=False, cache=cache)


def _pos(meta_or_tok):
    if isinstance(meta_or_tok, Token):
        return meta_or_tok.line, meta_or_tok.column
    return getattr(meta_or_tok, "line", 1), getattr(meta_or_tok, "column", 1)


_PRED_OPS = {"has", "has_no", "has_only", "is_", "served_at", "served_in", "served_before", "made_in",
             "made_with", "topped_with", "made_by", "cooked_in", "adds_before", "contains", "on", "within", "holds"}


@v_args(meta=True)
class _ToAst(Transformer):
    def start(self, meta, children):
        scope = children[0] if len(children) == 2 else None
        return A.Rule(*_pos(meta), scope, children[-1])

    def scope(self, meta, children):
        names = tuple(str(c) for c in children if isinstance(c, Token))
        conds = [c for c in children if not isinstance(c, Token)]
        return A.Scope(*_pos(meta), names, conds[0] if conds else None)

    def ifelse(self, meta, c):
        return A.IfElse(*_pos(meta), c[0], c[1], c[2])

    def any_of(self, meta, c):
        return c[0] if len(c) == 1 else A.AnyOf(*_pos(meta), tuple(c))

    def all_of(self, meta, c):
        return c[0] if len(c) == 1 else A.AllOf(*_pos(meta), tuple(c))

    def negate(self, meta, c):
        return A.Not(*_pos(meta), c[0])

    def true(self, meta, c):
        return A.Const(*_pos(meta), True)

    def false(self, meta, c):
        return A.Const(*_pos(meta), False)

    def subject(self, meta, c):
        return c[0]

    def count(self, meta, c):
        return A.Pred(*_pos(meta), "count", str(c[0]), (c[1], str(c[2]), int(c[3])))

    def available(self, meta, c):
        return A.Pred(*_pos(meta), "available", None, (c[0],))

    def free(self, meta, c):
        return A.Pred(*_pos(meta), "free", str(c[1]), (c[0],))

    def uses(self, meta, c):
        return A.Pred(*_pos(meta), "uses", None, (c[0],))

    def uses_in(self, meta, c):
        return A.Pred(*_pos(c[0]), "uses", str(c[0]), (c[1],))

    def task_has(self, meta, c):
        return A.Pred(*_pos(meta), "task_has", None, (_name(c[0]),))

    def made(self, meta, c):
        return A.Pred(*_pos(meta), "made", None, (_name(c[0]),))

    def each(self, meta, c):
        cls = c[1] if len(c) == 3 else None
        return A.Each(*_pos(meta), str(c[0]), cls, c[-1])

    def cls_any(self, meta, c):
        return c[0] if len(c) == 1 else A.ClsAny(*_pos(meta), tuple(c))

    def cls_all(self, meta, c):
        return c[0] if len(c) == 1 else A.ClsAll(*_pos(meta), tuple(c))

    def cls_neg(self, meta, c):
        return A.ClsNeg(*_pos(meta), c[0])

    def cls_mod(self, meta, c):
        return A.ClsMod(*_pos(meta), str(c[0]), c[1])

    def cls_name(self, meta, c):
        return _name(c[0])

    def __default__(self, data, children, meta):
        if data in _PRED_OPS:
            subj = children[0]
            args = tuple(_arg(data, a) for a in children[1:])
            return A.Pred(*_pos(subj), data.rstrip("_"), str(subj), args)
        return super().__default__(data, children, meta)


def _arg(op: str, a):
    if isinstance(a, Token):
        return str(a) if op in ("served_before", "contains") else _name(a)
    return a


def _name(tok: Token) -> A.ClsName:
    return A.ClsName(tok.line, tok.column, str(tok))


class RuleSyntaxError(AdaptError, ValueError):
    """A rule that does not parse: message, and 1-based line/col inside the rule text; `code` is the diagnostic."""

    code = "R001"

    def __init__(self, message: str, line: int, col: int):
        super().__init__(message)
        self.message, self.line, self.col = message, line, col


class RuleNumberError(RuleSyntaxError):
    """A number in a rule outside what a count can be (D111)."""

    code = "D111"


MAX_RULE_NUMBER = 10**6  # a count of things in one breakfast; larger is a typo (and 4300+ digits crash int())


def _check_numbers(tree) -> None:
    """Every number in a rule is a plausible count, checked on the token text before int() sees it."""
    for tok in tree.scan_values(lambda v: isinstance(v, Token) and v.type == "INT"):
        digits = str(tok).lstrip("0")
        if len(digits) > len(str(MAX_RULE_NUMBER)) or (digits and int(digits) > MAX_RULE_NUMBER):
            shown = str(tok) if len(tok) <= 20 else f"{str(tok)[:8]}...({len(tok)} digits)"
            raise RuleNumberError(f"number {shown} is out of range: a count in a rule is 0..{MAX_RULE_NUMBER:,}",
                                  tok.line, tok.column)


def _explain(exc: UnexpectedInput, text: str) -> str:
    if isinstance(exc, UnexpectedEOF):
        return "the rule ends too early; expected " + _expected(exc.expected)
    if isinstance(exc, UnexpectedCharacters):
        return f"unexpected character {text[exc.pos_in_stream]!r}"
    if isinstance(exc, UnexpectedToken):
        if exc.token.type == "$END":
            return "the rule ends too early; expected " + _expected(exc.expected)
        return f"unexpected '{exc.token}'; expected " + _expected(exc.expected)
    return str(exc)


_TERMINAL_WORDS = {"NAME": "a name", "INT": "a number", "CMP": "a comparison", "MOD": "heated/chopped",
                   "LPAR": "'('", "RPAR": "')'", "COLON": "':'", "COMMA": "','", "VBAR": "'|'",
                   "AMPERSAND": "'&'", "BANG": "'!'"}


def _expected(names) -> str:
    words = sorted({_TERMINAL_WORDS.get(n, f"'{n.lower()}'") for n in names})
    if len(words) > 6:
        words = words[:6] + ["..."]
    return ", ".join(words)


def parse_rule(text: str) -> A.Rule:
    """Parse rule text; raise RuleSyntaxError with a position and what was expected."""
    try:
        tree = parser().parse(text)
    except UnexpectedInput as exc:
        line = getattr(exc, "line", 1) or 1
        col = getattr(exc, "column", 1) or 1
        if isinstance(exc, UnexpectedEOF) or (isinstance(exc, UnexpectedToken) and exc.token.type == "$END"):
            lines = text.splitlines() or [""]
            line, col = len(lines), len(lines[-1]) + 1
        raise RuleSyntaxError(_explain(exc, text), line, col) from None
    _check_depth(tree)
    _check_numbers(tree)
    rule = _ToAst().transform(tree)
    return A.Rule(rule.line, rule.col, rule.scope, rule.expr, text)


MAX_RULE_DEPTH = 100


def _check_depth(tree) -> None:
    """Bound the nesting of a parsed rule before anything recursive walks it."""
    from lark import Tree

    stack = [(tree, 1)]
    while stack:
        node, depth = stack.pop()
        if depth > MAX_RULE_DEPTH:
            line, col = _pos(node.meta) if isinstance(node, Tree) else (1, 1)
            raise RuleSyntaxError(f"rule nested too deeply (more than {MAX_RULE_DEPTH} levels of brackets, "
                                  f"'not' and connectives); split it into simpler preferences", line or 1, col or 1)
        stack.extend((c, depth + 1) for c in node.children if isinstance(c, Tree))
