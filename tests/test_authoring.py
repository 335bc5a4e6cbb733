"""Authoring tools on the small test spec: the fixture checker, `adapt test`, `adapt new`, `adapt vocab` and
`adapt schema`."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest
import yaml

from adaptbench.cli import main
from adaptbench.compiler import compile_spec, load_domain
from adaptbench.qa.fixtures import check_fixture, find_fixtures, load_fixture, mutate, shape_problems

ROOT = Path(__file__).resolve().parents[1]
SMALL = ROOT / "tests" / "spec_small"


@pytest.fixture(scope="module")
def small():
    return load_domain(SMALL, use_cache=False)


@pytest.fixture
def spec(tmp_path, monkeypatch):
    """A copy of the small spec (with its fixtures) as ./spec."""
    shutil.copytree(SMALL, tmp_path / "spec")
    monkeypatch.chdir(tmp_path)
    return tmp_path / "spec"


def _ana(small):
    return load_fixture(SMALL / "fixtures" / "ana" / "scrambled_oat_milk.yaml")


def test_small_spec_fixtures_hold(small):
    paths = find_fixtures(SMALL / "fixtures")
    assert len(paths) >= 2
    for path in paths:
        assert check_fixture(small, load_fixture(path)) == [], path


def test_wrong_verdict_failed_action_and_unknown_preference_are_reported(small):
    fx = _ana(small)
    fx = {**fx, "expect": {"scrambled": "violated", "no_such_pref": "satisfied"},
          "actions": fx["actions"][:5] + ["Move pan_9 to stove_0"] + fx["actions"][5:], "mutations": []}
    problems = check_fixture(small, fx)
    assert any("'Move pan_9 to stove_0' failed" in p for p in problems)
    assert any(p.startswith("scrambled is satisfied, expected violated") for p in problems)
    assert any(p.startswith("unknown preference no_such_pref") for p in problems)


def test_a_mutation_naming_a_missing_action_is_reported(small):
    fx = {**_ana(small), "mutations": [{"remove": "Fly to the moon", "expect": {"scrambled": "violated"}}]}
    assert check_fixture(small, fx) == ["mutation 1: 'Fly to the moon' is not one of the actions"]


def test_unknown_persona_or_task(small):
    fx = {**_ana(small), "persona": "zoe"}
    assert check_fixture(small, fx) == ["unknown persona 'zoe'"]


@pytest.mark.parametrize("bad, says", [
    ({"task": "eggs", "actions": [], "expect": {"p": "satisfied"}}, "missing 'persona'"),
    ({"persona": "ana", "task": "eggs", "actions": [], "expect": {"p": "ok"}}, "must be satisfied"),
    ({"persona": "ana", "task": "eggs", "actions": [], "expect": {"p": "violated"}, "expcet": 1}, "unknown key"),
    ({"persona": "ana", "task": "eggs", "actions": [], "expect": {"p": "violated"},
      "mutations": [{"remove": "a", "swap": ["a", "b"], "expect": {"p": "violated"}}]}, "exactly one of"),
    ({"persona": "ana", "task": "eggs", "actions": "Look for eggs", "expect": {"p": "violated"}}, "list of action"),
    ([1, 2], "a fixture is a mapping"),
])
def test_shape_problems(bad, says):
    assert any(says in p for p in shape_problems(bad)), shape_problems(bad)


def test_mutations():
    acts = ["a", "b", "c"]
    assert mutate(acts, {"remove": "b"}) == ["a", "c"]
    assert mutate(acts, {"replace": ["b", "x"]}) == ["a", "x", "c"]
    assert mutate(acts, {"swap": ["a", "c"]}) == ["c", "b", "a"]


def test_adapt_test_passes_on_the_small_spec(spec, capsys):
    assert main(["test", "spec", "--workers", "1"]) == 0
    out = capsys.readouterr().out
    assert "fixtures  ok    2/2 hold" in out and out.strip().splitlines()[-1].startswith("ok: 4 checks passed")


def test_adapt_test_fails_on_a_broken_fixture(spec, capsys):
    path = spec / "fixtures" / "ana" / "scrambled_oat_milk.yaml"
    path.write_text(path.read_text().replace("scrambled: satisfied,", "scrambled: violated,"))
    assert main(["test", "spec", "--workers", "1"]) == 1
    out = capsys.readouterr().out
    assert "fixtures  FAIL  1/2 hold, 1 fail" in out
    assert f"{Path('spec/fixtures/ana/scrambled_oat_milk.yaml')}: scrambled is satisfied, expected violated" in out
    assert out.strip().splitlines()[-1].startswith("FAIL: fixtures")


def test_adapt_test_reports_a_stale_pending_fixture(spec, capsys):
    path = spec / "fixtures" / "ben" / "fried_in_butter.yaml"
    path.write_text(path.read_text() + 'pending: "the engine does not do this yet"\n')
    assert main(["test", "spec", "--fixtures", str(path), "--workers", "1"]) == 1
    assert "passes now: remove its `pending:` line" in capsys.readouterr().out


def test_adapt_test_runs_the_solvability_check(spec, capsys):
    """A preference the oracle cannot satisfy: salt in the eggs, which the small recipe never adds."""
    (spec / "personas" / "cy.yaml").write_text(
        "id: cy\nname: Cy\nnumber: 3\npreferences:\n"
        "  - {id: salted, text: Salt my eggs, rule: \"for eggs: it has salt\", topics: [salt]}\n")
    splits = spec / "splits.yaml"
    splits.write_text(splits.read_text().replace("unseen: [ben]", "unseen: [ben, cy]"))
    assert main(["test", "spec", "--seeds", "0", "--workers", "1"]) == 1
    out = capsys.readouterr().out
    assert "solvable  FAIL" in out and "cy/eggs seed 0: salted" in out


@pytest.mark.parametrize("kind", ["persona", "task"])
def test_new_skeletons_validate(spec, kind, capsys):
    assert main(["new", kind, "zoe", "--spec", "spec"]) == 0
    path = spec / ("personas" if kind == "persona" else "tasks") / "zoe.yaml"
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"wrote {path.relative_to(spec.parent)}"  # every file written or changed is named
    if kind == "persona":
        assert "unseen: [ana, zoe]" in (spec / "splits.yaml").read_text()  # every persona is unseen once
        assert out[1].startswith("changed spec/splits.yaml: added zoe"), out
    else:
        assert not any(line.startswith("changed") for line in out), out
    assert "TODO" in path.read_text() and path.read_text().startswith("#")
    domain, diags = compile_spec([spec])
    assert domain is not None, [d.render() for d in diags]
    assert not [d for d in diags if d.severity == "error"]
    before = path.read_text()
    assert main(["new", kind, "zoe", "--spec", "spec"]) != 0  # never overwrites
    assert path.read_text() == before


def test_new_rejects_a_bad_or_taken_id(spec, capsys):
    assert main(["new", "persona", "Zoe-2", "--spec", "spec"]) == 2
    assert main(["new", "persona", "ana", "--spec", "spec"]) == 2
    assert "already exists" in capsys.readouterr().err


def test_vocab_lists_names_and_what_they_match(capsys):
    assert main(["vocab", "--spec", str(SMALL), "--tags"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("tags:\n") and "categories:" not in out
    assert re.search(r"^  cookware +pans, pots and skillets.*; pan_0, pan_1$", out, re.M), out
    assert main(["vocab", "--spec", str(SMALL), "--components", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert dict(data["components"])["egg_dish"] == "group: eggs"


def test_schemas_carry_the_declared_names(tmp_path, capsys):
    assert main(["schemas", "--spec", str(SMALL), "--out", str(tmp_path / ".schemas")]) == 0
    objects = json.loads((tmp_path / ".schemas" / "objects.schema.json").read_text())
    item = objects["properties"]["objects"]["items"]["properties"]
    assert "description" in item["category"] and "description" in item["tags"]
    tags = {c["const"] for c in item["tags"]["items"]["anyOf"]}
    assert {"cookware", "dining_place"} <= tags
    assert {c["const"] for c in item["location"]["anyOf"]} >= {"fridge_0", "egg_carton_0"}
    tasks = json.loads((tmp_path / ".schemas" / "tasks.schema.json").read_text())
    comps = tasks["properties"]["tasks"]["items"]["properties"]["components"]["items"]["anyOf"]
    assert [c["const"] for c in comps] == ["eggs"]


def test_the_enriched_schemas_accept_the_spec_they_describe(tmp_path):
    """An editor using them must not flag the spec's own files."""
    import jsonschema

    from adaptbench.authoring import schemas
    from adaptbench.compiler.loader import KINDS, spec_files

    docs = schemas(load_domain(SMALL, use_cache=False))
    for kind, path in spec_files([SMALL]):
        jsonschema.validate(yaml.safe_load(path.read_text()), docs[f"{KINDS.get(kind, kind)}.schema.json"])


@pytest.mark.paper
def test_the_fixture_example_in_the_docs_holds(domain):
    text = (ROOT / "docs" / "fixtures.md").read_text()
    fx = yaml.safe_load(re.findall(r"```yaml\n(.*?)```", text, re.S)[0])
    assert shape_problems(fx) == [] and check_fixture(domain, fx) == []
