"""Hand-written replay trajectories: each persona preference shown satisfied in one trajectory,
violated in another (and inapplicable where the rule has a condition).

Fixtures live in tests/fixtures/trajectories/<persona>/*.yaml:

    persona: juan
    task: eggs
    scene: full            # or: seed: 3 (a sampled scene)
    actions: [...]
    expect: {preference_id: satisfied | violated | inapplicable}
    mutations:             # optional: edit the actions and the verdicts must flip
      - remove: "Pour whole_milk from milk_0 to pan_1"
        expect: {whole_milk_in_eggs: violated}
      - replace: ["Pour whole_milk from milk_0 to pan_1", "Pour oat_milk from milk_1 to pan_1"]
        expect: {...}
      - swap: ["line a", "line b"]     # exchange the positions of two actions
        expect: {...}
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


def _verdicts(domain, fx: dict, actions: list, label: str) -> dict:
    full = fx.get("scene", "full" if "seed" not in fx else "sampled") == "full"
    env = Env(domain, task=fx["task"], persona=fx["persona"], seed=fx.get("seed"), full_scene=full)
    env.reset()
    for action in actions:
        r = env.step(action)
        assert r.ok, f"{label}: '{action}' failed: {r.observation}"
    return {v.id: v for v in env.evaluate().verdicts}


def _check(verdicts: dict, expect: dict, label: str) -> None:
    for pref, want in expect.items():
        assert pref in verdicts, f"{label}: unknown preference {pref}"
        assert verdicts[pref].verdict == want, f"{label}: {pref} is {verdicts[pref].verdict}: {verdicts[pref].reason}"


def mutate(actions: list, m: dict) -> list:
    """Apply one mutation (remove / replace / swap) to an action list."""
    out = list(actions)
    if "remove" in m:
        out.remove(m["remove"])
    elif "replace" in m:
        old, new = m["replace"]
        out[out.index(old)] = new
    elif "swap" in m:
        a, b = m["swap"]
        i, j = out.index(a), out.index(b)
        out[i], out[j] = out[j], out[i]
    return out


@pytest.mark.parametrize("path", FILES, ids=[f"{p.parent.name}/{p.stem}" for p in FILES])
def test_trajectory_verdicts(domain, path):
    fx = _load(path)
    _check(_verdicts(domain, fx, fx["actions"], path.name), fx["expect"], path.name)
    for k, m in enumerate(fx.get("mutations", ())):
        label = f"{path.name} mutation {k + 1}"
        _check(_verdicts(domain, fx, mutate(fx["actions"], m), label), m["expect"], label)


def _coverage():
    seen: dict = {}
    for path in FILES:
        fx = _load(path)
        for pref, want in fx["expect"].items():
            seen.setdefault((fx["persona"], pref), set()).add(want)
    return seen


@pytest.mark.parametrize("persona", ["juan", "ron", "maya", "ethan"])
def test_every_preference_is_shown_satisfied_and_violated(domain, persona):
    """Issue 2's four personas; test_all_personas_have_fixtures widens this to all 16."""
    if persona not in domain.persona:
        pytest.fail(f"persona {persona} is missing from the spec")
    seen = _coverage()
    for pref in domain.persona[persona].preferences:
        got = seen.get((persona, pref.id), set())
        assert {"satisfied", "violated"} <= got, f"{persona}.{pref.id}: fixtures show only {sorted(got)}"


def test_all_personas_have_fixtures(domain):
    """Issue 3: every preference of all 16 personas — satisfied and violated (inapplicable too, since every
    rule has a task scope); a preference that applies to no shipped task can only be shown inapplicable."""
    from adaptbench.compiler.lint import applies_to

    seen = _coverage()
    missing = []
    for persona in domain.personas:
        for pref in persona.preferences:
            got = seen.get((persona.id, pref.id), set())
            applies = [applies_to(domain, pref, t) for t in domain.tasks]
            conditional = pref.rule.scope is not None and pref.rule.scope.cond is not None
            if not any(applies):
                want = {"inapplicable"}
            elif all(applies) and not conditional:  # e.g. `for all: ...` can never be inapplicable
                want = {"satisfied", "violated"}
            else:
                want = {"satisfied", "violated", "inapplicable"}
            if not want <= got:
                missing.append(f"{persona.id}.{pref.id} (has {sorted(got)})")
    assert not missing, f"{len(missing)} preferences lack fixtures: " + "; ".join(missing[:20])
