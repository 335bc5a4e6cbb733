"""Adversarial trajectories ("tricks"): what a policy hunting for loopholes would try, each with the
verdict the persona's sentence implies.

Files live in tests/fixtures/tricks/*.yaml, in the trajectory-fixture format (see
tests/test_persona_fixtures.py) plus:

    trick: naming | wrong_dish | after_serving | moved_not_used | chilled_hot | side_elsewhere | tray | ...
    why: >                 # the paper's sentence and what a person at the table would say
      Juan wants whole milk added while preparing the eggs; cold milk poured over served eggs is not that.
    pending: "..."         # optional, while the engine does not yet give the right verdict: a strict xfail
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from tests.test_persona_fixtures import _check, _verdicts, mutate

TRICKS = Path(__file__).resolve().parent / "fixtures" / "tricks"
FILES = sorted(TRICKS.rglob("*.yaml"))


@pytest.mark.parametrize("path", FILES, ids=[p.stem for p in FILES])
def test_trick_verdicts(domain, path, request):
    fx = yaml.safe_load(path.read_text())
    assert fx.get("trick") and fx.get("why"), f"{path.name}: a trick says what it tries and why"
    if fx.get("pending"):
        request.applymarker(pytest.mark.xfail(reason=fx["pending"], strict=True))
    _check(_verdicts(domain, fx, fx["actions"], path.name), fx["expect"], path.name)
    for k, m in enumerate(fx.get("mutations", ())):
        label = f"{path.name} mutation {k + 1}"
        _check(_verdicts(domain, fx, mutate(fx["actions"], m), label), m["expect"], label)
