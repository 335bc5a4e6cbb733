"""The linter: applicability matrix, preferences for no task, empty classes, conflicting pairs."""

from __future__ import annotations

from adaptbench.compiler.lint import lint, matrix
from adaptbench.compiler.model import Persona, Preference, Where
from adaptbench.compiler.rules import parse_rule


def _with(domain, *rules):
    from dataclasses import replace

    prefs = tuple(Preference(f"p{i}", "t", parse_rule(r), ("x",)) for i, r in enumerate(rules))
    persona = Persona("zed", "Zed", 99, "", prefs)
    where = {("rule", "zed", p.id): Where("spec/personas/zed.yaml", i + 1, 1) for i, p in enumerate(prefs)}
    return replace(domain, personas=(persona,)), where


def test_matrix_counts_applicable_preferences(domain):
    rows = dict(matrix(domain))
    assert len(rows) == 16
    juan = rows["juan"]
    tasks = [t.id for t in domain.tasks]
    assert juan[tasks.index("toast_coffee")] > juan[tasks.index("cereal")] - 10


def test_warns_for_no_task_and_errors_for_empty_class(domain):
    d, where = _with(domain, "for pancakes: it has honey", "for coffee: it has milk & vegan & dairy")
    codes = {(x.code, x.severity, x.line) for x in lint(d, where)}
    assert ("L001", "warning", 1) in codes
    assert any(c == "L002" and s == "error" for c, s, _ in codes)


def test_warns_for_preferences_that_cannot_both_hold(domain):
    d, where = _with(domain, "for coffee: it has whole_milk", "for coffee: it has no milk",
                     "for cereal: it adds milk before cereal", "for cereal: it adds cereal before milk",
                     "for all: beverage served before food", "for all: food served before beverage")
    msgs = [x.message for x in lint(d, where) if x.code == "L003"]
    assert len(msgs) == 3
    assert any("forbids milk" in m for m in msgs) and any("opposite orders" in m for m in msgs)


def test_shipped_personas_lint_clean_of_errors(domain):
    from adaptbench.compiler import compile_spec

    from ..conftest import SPEC

    _, diags = compile_spec([SPEC])
    assert not [d for d in diags if d.severity == "error"]
