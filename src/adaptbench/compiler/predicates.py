"""Every predicate of the rule language, declared once: its name, where it may be used, its syntax
(the grammar alternatives of `rules.lark` that read it, with their argument kinds) and the forms
`docs/rules.md` documents it by.

The compiler's checks take the contexts from here (`ops_for`), and each evaluator table registers its
evaluators by these names (`evaluators`): preference and completion verdicts in `runtime.verify`,
action preconditions in `runtime.actions`. `tests/compiler/test_predicates.py` checks that the
grammar, the checks, the evaluators and the docs agree with these declarations.

Contexts: `precondition` (action `check:` rules; subjects are slots), `dish` (component completion
and style rules; the subject is `it`), `preference` (persona rules). Argument kinds: `subject` (a
subject name), `class` (a class expression), `name` (a bare name: a verb group, a component or a
subject), `cmp` (a comparison), `int`, `expr` (a nested rule expression). `QUANTIFIERS` declares the
constructs that read like predicates but quantify over dishes (`each`).
"""

from __future__ import annotations

from dataclasses import dataclass

CONTEXTS = ("precondition", "dish", "preference")
EVALUATOR_CONTEXTS = {"verdict": ("dish", "preference"), "precondition": ("precondition",)}


@dataclass(frozen=True)
class Predicate:
    """One predicate: `name` (the AST op), `contexts` it may be used in, `syntax` = ((grammar alias,
    argument kinds), ...), and `docs` = the forms docs/rules.md lists it under."""

    name: str
    contexts: tuple
    syntax: tuple
    docs: tuple


_DP = ("dish", "preference")
_P = ("preference",)
_SC = ("subject", "class")

PREDICATES = {p.name: p for p in (
    Predicate("has", _DP, (("has", _SC),), ("S has X",)),
    Predicate("has_no", _DP, (("has_no", _SC),), ("S has no X",)),
    Predicate("has_only", _DP, (("has_only", _SC),), ("S has only X",)),
    Predicate("count", _DP, (("count", ("subject", "class", "cmp", "int")),), ("count(S, X) >= N",)),
    Predicate("is", ("precondition", "dish", "preference"), (("is_", _SC),), ("S is STYLE", "x is X")),
    Predicate("made_in", _DP, (("made_in", _SC),), ("S made in X",)),
    Predicate("made_with", _DP, (("made_with", _SC),), ("S made with X",)),
    Predicate("topped_with", _DP, (("topped_with", _SC),), ("S topped with X",)),
    Predicate("made_by", _DP, (("made_by", ("subject", "name")),), ("S made by G",)),
    Predicate("cooked_in", _DP, (("cooked_in", _SC),), ("S cooked in X",)),
    Predicate("adds_before", _DP, (("adds_before", ("subject", "class", "class")),), ("S adds X before Y",)),
    Predicate("served_at", _P, (("served_at", _SC),), ("S served at P",)),
    Predicate("served_in", _P, (("served_in", _SC),), ("S served in X",)),
    Predicate("served_before", _P, (("served_before", ("subject", "subject")),), ("S served before T",)),
    Predicate("available", _P, (("available", ("class",)),), ("available X",)),
    Predicate("free", _P, (("free", ("class", "subject")),), ("free X for S",)),
    Predicate("uses", _P, (("uses", ("class",)), ("uses_in", _SC)), ("uses X", "S uses X")),
    Predicate("task_has", _P, (("task_has", ("name",)),), ("task has C",)),
    Predicate("made", _P, (("made", ("name",)),), ("made C",)),
    Predicate("contains", ("precondition",), (("contains", ("subject", "subject")),), ("y contains x",)),
    Predicate("on", ("precondition",), (("on", _SC),), ("x on X",)),
    Predicate("within", ("precondition",), (("within", _SC),), ("x within X",)),
    Predicate("holds", ("precondition",), (("holds", _SC),), ("x holds X",)),
)}


# Constructs that are not predicates of one subject but read like them (their own AST node and evaluator).
QUANTIFIERS = {q.name: q for q in (
    Predicate("each", _P, (("each", ("name", "class", "expr")),), ("each S [with X] (E)",)),
)}


def ops_for(context: str) -> frozenset:
    """The predicate names allowed in a context ("precondition", "dish" or "preference")."""
    if context not in CONTEXTS:
        raise ValueError(f"unknown rule context '{context}' (one of {', '.join(CONTEXTS)})")
    return frozenset(p.name for p in PREDICATES.values() if context in p.contexts)


def evaluator_names(kind: str) -> frozenset:
    """The predicates an evaluator table of `kind` ("verdict" or "precondition") must cover."""
    return frozenset().union(*(ops_for(c) for c in EVALUATOR_CONTEXTS[kind]))


def evaluators(kind: str, table: dict) -> dict:
    """Register an evaluator table by predicate name: every name must be declared here and every
    predicate of the kind's contexts must have an evaluator (a mismatch fails at import, naming it)."""
    expected = evaluator_names(kind)
    unknown, missing = set(table) - expected, expected - set(table)
    if unknown or missing:
        raise RuntimeError(f"{kind} evaluators disagree with compiler/predicates.py: "
                           f"undeclared {sorted(unknown)}, without an evaluator {sorted(missing)}")
    return dict(table)
