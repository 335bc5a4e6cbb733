"""Hand-written replay trajectories: each persona preference shown satisfied in one trajectory,
violated in another (and inapplicable where the rule has a condition).

Fixtures live in tests/fixtures/trajectories/<persona>/*.yaml:

    persona: juan
    task: eggs
    scene: full            # or: seed: 3
    actions: [...]
    expect: {preference_id: satisfied | violated | inapplicable}
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from adaptbench.runtime.env import Env

FIXTURES = Path(__file__).resolve().parent / "fixtures" / "trajectories"
FILES = sorted(FIXTURES.rglob("*.yaml"))


def _load(path: Path) -> dict:
    return yaml.safe_load(path.read_text())


@pytest.mark.parametrize("path", FILES, ids=[f"{p.parent.name}/{p.stem}" for p in FILES])
def test_trajectory_verdicts(domain, path):
    fx = _load(path)
    full = fx.get("scene", "full") == "full"
    env = Env(domain, task=fx["task"], persona=fx["persona"], seed=fx.get("seed"), full_scene=full)
    env.reset()
    for action in fx["actions"]:
        r = env.step(action)
        assert r.ok, f"{path.name}: '{action}' failed: {r.observation}"
    verdicts = {v.id: v for v in env.evaluate().verdicts}
    for pref, want in fx["expect"].items():
        assert pref in verdicts, f"{path.name}: unknown preference {pref}"
        assert verdicts[pref].verdict == want, f"{path.name}: {pref}: {verdicts[pref].reason}"


def _coverage():
    seen: dict = {}
    for path in FILES:
        fx = _load(path)
        for pref, want in fx["expect"].items():
            seen.setdefault((fx["persona"], pref), set()).add(want)
    return seen


@pytest.mark.parametrize("persona", ["juan", "ron", "maya", "ethan"])
def test_every_preference_is_shown_satisfied_and_violated(domain, persona):
    if persona not in domain.persona:
        pytest.fail(f"persona {persona} is missing from the spec")
    seen = _coverage()
    for pref in domain.persona[persona].preferences:
        got = seen.get((persona, pref.id), set())
        assert {"satisfied", "violated"} <= got, f"{persona}.{pref.id}: fixtures show only {sorted(got)}"
