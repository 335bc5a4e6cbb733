"""Broken specs give the right diagnostics: each case overlays files on the small test spec."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from adaptbench.cli import main
from adaptbench.compiler import compile_spec

HERE = Path(__file__).resolve().parent
FIXTURES = HERE.parent / "fixtures" / "bad"
SPEC = HERE.parents[1] / "tests" / "spec_small"  # the small test spec: the paper spec may grow freely
CASES = sorted(p.name for p in FIXTURES.iterdir() if p.is_dir())


def _overlay(tmp_path: Path, case: str) -> Path:
    spec = tmp_path / "spec"
    shutil.copytree(SPEC, spec, ignore=shutil.ignore_patterns("fixtures"))
    for f in (FIXTURES / case).rglob("*.yaml"):
        target = spec / f.relative_to(FIXTURES / case)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(f, target)
    return spec


@pytest.mark.parametrize("case", CASES)
def test_bad_spec_diagnostics_match_snapshot(case, tmp_path, monkeypatch, capsys, golden):
    _overlay(tmp_path, case)
    monkeypatch.chdir(tmp_path)
    status = main(["validate", "spec"])
    out = capsys.readouterr()
    assert status == 1
    golden(FIXTURES / case / "expected.txt", out.err)


@pytest.mark.parametrize("case", CASES)
def test_every_diagnostic_points_into_the_overlay(case, tmp_path, monkeypatch):
    _overlay(tmp_path, case)
    monkeypatch.chdir(tmp_path)
    domain, diags = compile_spec(["spec"])
    assert domain is None
    overlay = {str(Path("spec") / f.relative_to(FIXTURES / case)) for f in (FIXTURES / case).rglob("*.yaml")}
    assert diags and {d.path for d in diags} <= overlay


def test_json_format_lists_code_and_position(tmp_path, monkeypatch, capsys):
    import json

    _overlay(tmp_path, "unknown_name_in_rule")
    monkeypatch.chdir(tmp_path)
    assert main(["validate", "spec", "--format", "json"]) == 1
    rows = json.loads(capsys.readouterr().out)
    assert rows[0] == {"path": "spec/personas/zed.yaml", "line": 7, "col": 33, "code": "D104",
                       "message": "unknown name 'mlk' (did you mean 'milk'?)", "severity": "error"}


def test_usage_error_exits_2(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["validate", "--format", "xml"])
    assert exc.value.code == 2
