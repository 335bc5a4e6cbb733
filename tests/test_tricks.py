"""Adversarial trajectories ("tricks") of the shipped spec: what a policy hunting for loopholes would try,
each with the verdict the persona's sentence implies. Files live in spec/fixtures/tricks/*.yaml, in the
fixture format (docs/fixtures.md) plus `trick:`, `why:` and optionally `pending:` (a strict xfail while
the engine does not yet give the right verdict)."""

from __future__ import annotations

from pathlib import Path

import pytest

from adaptbench.qa.fixtures import check_fixture, find_fixtures, load_fixture

pytestmark = pytest.mark.paper

TRICKS = Path(__file__).resolve().parents[1] / "spec" / "fixtures" / "tricks"
FILES = find_fixtures(TRICKS)


@pytest.mark.parametrize("path", FILES, ids=[p.stem for p in FILES])
def test_trick_verdicts(domain, path, request):
    fx = load_fixture(path)
    assert fx.get("trick") and fx.get("why"), f"{path.name}: a trick says what it tries and why"
    if fx.get("pending"):
        request.applymarker(pytest.mark.xfail(reason=fx["pending"], strict=True))
    problems = check_fixture(domain, fx)
    assert not problems, f"{path.name}: " + "; ".join(problems)
