"""Each rule-language predicate is declared once (compiler/predicates.py); the grammar, the compiler's
checks, the evaluators and docs/rules.md agree with the declarations."""

from __future__ import annotations

import re
from importlib import resources
from pathlib import Path

import pytest

from adaptbench.compiler import checks
from adaptbench.compiler import predicates as P
from adaptbench.compiler.rules import parse_rule
from adaptbench.runtime import actions, verify

DOCS = Path(__file__).resolve().parents[2] / "docs" / "rules.md"
_KINDS = {"subject": "subject", "cls": "class", "NAME": "name", "CMP": "cmp", "INT": "int", "expr": "expr"}
_DECLARED = [*P.PREDICATES.values(), *P.QUANTIFIERS.values()]


def _grammar_alternatives() -> dict:
    """alias -> argument kinds of every `-> alias` alternative of the atom rule in rules.lark."""
    text = resources.files("adaptbench.compiler").joinpath("rules.lark").read_text()
    atom = text[text.index("?atom:"):text.index("subject: NAME")]
    out = {}
    for line in atom.splitlines():
        m = re.search(r"\|\s*(.*?)\s*->\s*(\w+)\s*$", line)
        if m and m.group(2) not in ("true", "false"):
            body = re.sub(r'"[^"]*"', " ", m.group(1))
            out[m.group(2)] = tuple(_KINDS[t] for t in re.findall(r"[A-Za-z_]+", body))
    return out


def test_the_grammar_reads_exactly_the_declared_predicates():
    declared = {alias: kinds for p in _DECLARED for alias, kinds in p.syntax}
    assert _grammar_alternatives() == declared


def test_the_checks_take_their_contexts_from_the_declarations():
    assert {n for n, p in P.PREDICATES.items() if "precondition" in p.contexts} == checks.PRE_OPS
    assert {n for n, p in P.PREDICATES.items() if "dish" in p.contexts} == checks.DISH_OPS
    assert {n for n, p in P.PREDICATES.items() if "preference" in p.contexts} == checks.PREF_OPS
    assert checks.DISH_OPS <= checks.PREF_OPS  # a completion predicate is also a preference predicate


def test_every_declared_predicate_has_its_evaluators_and_no_more():
    assert set(verify._PREDS) == P.evaluator_names("verdict")
    assert set(actions._PRED) == P.evaluator_names("precondition")
    assert set(verify._PREDS) | set(actions._PRED) == set(P.PREDICATES)


def test_registering_an_undeclared_or_incomplete_table_fails_loudly():
    with pytest.raises(RuntimeError, match="undeclared \\['smells'\\]"):
        P.evaluators("precondition", {**actions._PRED, "smells": None})
    with pytest.raises(RuntimeError, match="without an evaluator \\['holds'\\]"):
        P.evaluators("precondition", {k: v for k, v in actions._PRED.items() if k != "holds"})


def _documented() -> set:
    text = DOCS.read_text()
    section = text[text.index("## Predicates"):text.index("## Preference rules")]
    rows = re.findall(r"^\| `([^`]+)` \|", section, flags=re.M)
    return {r for r in rows if r not in ("true",)}


def test_docs_list_exactly_the_declared_forms():
    declared = {form for p in _DECLARED for form in p.docs}
    assert _documented() == declared


_SAMPLES = {"has": "it has milk", "has_no": "it has no milk", "has_only": "it has only milk",
            "count": "count(it, spice) >= 2", "is_": "it is hot", "made_in": "it made in pot",
            "made_with": "it made with milk", "topped_with": "it topped with milk", "made_by": "it made by folding",
            "cooked_in": "it cooked in pan", "adds_before": "it adds milk before cereal",
            "served_at": "it served at patio", "served_in": "it served in mug",
            "served_before": "coffee served before food", "available": "available toaster",
            "free": "free (fancy & plate) for it", "uses": "uses toaster",
            "uses_in": "it uses toaster", "task_has": "task has toast", "made": "made toast",
            "contains": "y contains x", "on": "x on stove", "within": "x within stove", "holds": "x holds water"}


def test_quantifiers_parse_to_their_node():
    from adaptbench.compiler import ast as A

    assert isinstance(parse_rule("for egg_dish: each sides with vegetable (it is hot)").expr, A.Each)


@pytest.mark.parametrize("name", sorted(P.PREDICATES))
def test_each_declared_syntax_parses_to_its_predicate(name):
    for alias, _kinds in P.PREDICATES[name].syntax:
        assert parse_rule(_SAMPLES[alias]).expr.op == name, alias


@pytest.mark.parametrize("rule,message", [
    ("for eggs: not free (stainless | table_0) for it", "not a movable container"),
    ("for eggs: not free milk for it", "not a movable container"),
    ("for eggs: not free heated plate for it", "'heated' describes an ingredient"),
    ("for eggs: not free (plate & cookware) for it", "matches no object"),
])
def test_free_names_vessels_or_is_d112(domain, rule, message):
    """`free X for S` is about vessels: a class that also matches furniture or food is a located D112."""
    from adaptbench.compiler.build import Draft

    draft = Draft()
    checks._check_rule(draft, parse_rule(rule), "preference", _names(domain))
    assert [d.code for d in draft.diags] == ["D112"], draft.diags
    assert message in draft.diags[0].message and draft.diags[0].col > 1


def _names(domain):
    from adaptbench.compiler.build import Draft

    draft = Draft(entities=list(domain.entities), substances=list(domain.substances),
                  tags={t: "" for e in domain.entities for t in e.tags} | {t: "" for s in domain.substances for t in s.tags},
                  categories={e.category: "" for e in domain.entities} | {s.category: "" for s in domain.substances},
                  components=list(domain.components))
    return checks.Names(draft)


def test_free_parses_with_its_subject():
    rule = parse_rule("for all: each meal (it served in fancy or not free (fancy & plate) for it)")
    free = rule.expr.expr.items[1].item
    assert (free.op, free.subject) == ("free", "it")
