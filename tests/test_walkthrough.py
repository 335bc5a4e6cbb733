"""The authoring walk-through of docs/authoring.md, performed on a copy of spec/: every file it shows is
written as shown, then nothing but the docs' commands run. No Python is edited; existing scenes do not
change; the author's fixtures hold; the oracle satisfies the new persona on every task and every persona on
the new tasks; the engine's own tests (on tests/spec_small) are untouched by construction."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from adaptbench.cli import main
from adaptbench.compiler import compile_spec, load_domain
from adaptbench.qa.spectest import run_tests
from adaptbench.runtime.scene import sample_scene

pytestmark = pytest.mark.paper

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "authoring.md"


def walkthrough_files() -> dict:
    """{path under the spec: text} for every ```yaml block of the walk-through whose first line names a file."""
    section = DOC.read_text().split("## Walk-through", 1)[1]
    out = {}
    for block in re.findall(r"```yaml\n(.*?)```", section, re.S):
        first, _, body = block.partition("\n")
        m = re.fullmatch(r"# spec/(\S+\.yaml)", first.strip())
        if m:
            out[m.group(1)] = body
    return out


@pytest.fixture(scope="module")
def extended(tmp_path_factory):
    spec = tmp_path_factory.mktemp("walk") / "spec"
    shutil.copytree(ROOT / "spec", spec)
    for rel, text in walkthrough_files().items():
        assert rel == "splits.yaml" or not (spec / rel).exists(), f"the walk-through adds files; {rel} exists"
        (spec / rel).parent.mkdir(parents=True, exist_ok=True)
        (spec / rel).write_text(text)
    return spec


def test_the_walkthrough_shows_objects_tasks_a_persona_and_fixtures():
    files = walkthrough_files()
    kinds = {rel.split("/")[0] for rel in files}
    assert {"objects", "tasks", "personas", "fixtures", "splits.yaml"} <= kinds, sorted(files)


def test_the_walkthrough_only_adds_zoe_to_the_splits():
    old = (ROOT / "spec" / "splits.yaml").read_text()
    new = walkthrough_files()["splits.yaml"]
    strip = [ln.replace(", zoe", "") for ln in new.splitlines()]
    assert [ln for ln in old.splitlines() if not ln.startswith("#")] == strip and ", zoe" in new


def test_the_extension_validates(extended):
    domain, diags = compile_spec([extended])
    assert domain is not None, [d.render() for d in diags if d.severity == "error"]
    _, base = compile_spec([ROOT / "spec"])
    new = {(d.code, d.message) for d in diags} - {(d.code, d.message) for d in base}
    assert not new, f"the extension brings new warnings: {sorted(new)}"
    assert {"chia_pudding_tea", "coffee_only"} <= set(domain.task) and "zoe" in domain.persona
    assert "chia_pudding" in {c.id for c in domain.components}


def test_existing_scenes_are_unchanged(extended):
    base, ext = load_domain(ROOT / "spec", use_cache=False), load_domain(extended, use_cache=False)
    added = {e.id for e in ext.entities} - {e.id for e in base.entities}
    for seed in range(20):
        before = {o["id"]: o["location"] for o in sample_scene(base, seed, False).as_dict(base)["objects"]}
        after = {o["id"]: o["location"] for o in sample_scene(ext, seed, False).as_dict(ext)["objects"]}
        assert {k: v for k, v in after.items() if k not in added} == before, f"seed {seed}"


def test_adapt_test_passes_on_the_authors_additions(extended, capsys):
    fixtures = extended / "fixtures" / "trajectories" / "zoe"
    zoe = run_tests(extended, fixtures, seeds=[0], personas=["zoe"])
    assert zoe.ok, zoe.render()
    new_tasks = run_tests(extended, fixtures, seeds=[0], tasks=["chia_pudding_tea", "coffee_only"])
    assert new_tasks.ok, new_tasks.render()
    assert main(["test", str(extended), "--fixtures", str(fixtures), "--personas", "zoe", "--seeds", "0",
                 "--workers", "1"]) == 0
    assert "fixtures  ok    2/2 hold" in capsys.readouterr().out


def test_the_new_objects_are_used(extended):
    """The fixtures really make chia pudding from the new objects (not a recipe that skips them)."""
    text = (extended / "fixtures" / "trajectories" / "zoe" / "chia_pudding_tea.yaml").read_text()
    assert "chia_seeds_0" in text
