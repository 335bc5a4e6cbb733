"""The shipped spec's trajectory fixtures (spec/fixtures/trajectories/<persona>/*.yaml, format in
docs/fixtures.md): each persona preference shown satisfied in one trajectory, violated in another (and
inapplicable where the rule has a condition). The loader and checker are `adaptbench.qa.fixtures`, the
same code `adapt test` runs."""

from __future__ import annotations

from pathlib import Path

import pytest

from adaptbench.qa.fixtures import check_fixture, coverage, find_fixtures, load_fixture

pytestmark = pytest.mark.paper

ROOT = Path(__file__).resolve().parents[1]
FIXTURES = ROOT / "spec" / "fixtures" / "trajectories"
FILES = find_fixtures(FIXTURES)


def test_fixtures_live_next_to_the_spec():
    """Fixtures moved to spec/fixtures/ (where `adapt test spec` finds them); one left in the old place would
    silently stop being checked."""
    old = [p for d in ("trajectories", "tricks") for p in (ROOT / "tests" / "fixtures" / d).rglob("*.y*ml")]
    assert not old, f"move these under spec/fixtures/: {[str(p.relative_to(ROOT)) for p in old]}"


@pytest.mark.parametrize("path", FILES, ids=[f"{p.parent.name}/{p.stem}" for p in FILES])
def test_trajectory_verdicts(domain, path):
    problems = check_fixture(domain, load_fixture(path))
    assert not problems, f"{path.name}: " + "; ".join(problems)


@pytest.mark.parametrize("persona", ["juan", "ron", "maya", "ethan"])
def test_every_preference_is_shown_satisfied_and_violated(domain, persona):
    """Issue 2's four personas; test_all_personas_have_fixtures widens this to all 16."""
    if persona not in domain.persona:
        pytest.fail(f"persona {persona} is missing from the spec")
    seen = coverage(FILES)
    for pref in domain.persona[persona].preferences:
        got = seen.get((persona, pref.id), set())
        assert {"satisfied", "violated"} <= got, f"{persona}.{pref.id}: fixtures show only {sorted(got)}"


def test_all_personas_have_fixtures(domain):
    """Issue 3: every preference of all 16 personas — satisfied and violated (inapplicable too, since every
    rule has a task scope); a preference that applies to no shipped task can only be shown inapplicable."""
    from adaptbench.compiler.lint import applies_to

    seen = coverage(FILES)
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
