"""adaptbench as a library: one error base, the paper's spec inside the package, progress off a terminal."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

import pytest

from adaptbench import errors, paper

ROOT = Path(__file__).resolve().parents[1]
SMALL = ROOT / "tests" / "spec_small"


def _errors() -> list:
    from adaptbench.compiler.diagnostics import SpecError
    from adaptbench.compiler.rules import RuleSyntaxError
    from adaptbench.harness.plots import PlotsUnavailable
    from adaptbench.harness.record import RecordError
    from adaptbench.harness.records import RunsError
    from adaptbench.harness.registry import UnknownAgent
    from adaptbench.harness.results import DiskFull, ResultsError
    from adaptbench.harness.workers import WorkerDied
    from adaptbench.qa.fixtures import FixtureError
    from adaptbench.runtime.actions import ActionFailed

    return [(SpecError, ValueError), (RuleSyntaxError, ValueError), (RecordError, ValueError),
            (FixtureError, ValueError), (UnknownAgent, KeyError), (PlotsUnavailable, RuntimeError),
            (WorkerDied, RuntimeError), (ResultsError, Exception), (DiskFull, Exception), (RunsError, Exception),
            (ActionFailed, Exception)]


@pytest.mark.parametrize(("cls", "builtin"), _errors(), ids=lambda x: x.__name__)
def test_every_error_has_the_one_base_and_the_builtin_it_behaves_as(cls, builtin):
    assert issubclass(cls, errors.AdaptError) and issubclass(cls, builtin)
    assert cls.exit_code in (1, 2)


def test_the_cli_handler_turns_any_adapt_error_into_one_line_and_its_exit_code(capsys, monkeypatch):
    import importlib

    from adaptbench.cli import main

    def boom(args):
        raise errors.AdaptError("the thing is broken", code=2)

    monkeypatch.setattr(importlib.import_module("adaptbench.cli.episode"), "_cmd_scene", boom)
    assert main(["scene", "--seed", "0"]) == 2
    assert capsys.readouterr().err == "adapt: the thing is broken\n"


def test_the_default_spec_is_the_shipped_one_and_adapt_spec_overrides(monkeypatch):
    monkeypatch.delenv(paper.SPEC_ENV, raising=False)
    assert Path(paper.default_spec()) == paper.shipped_spec() == ROOT / "spec"  # a checkout: the repository's
    assert Path(paper.default_grammars()) == ROOT / "grammars"
    monkeypatch.setenv(paper.SPEC_ENV, str(SMALL))
    assert paper.default_spec() == str(SMALL)
    from adaptbench.compiler import load_domain

    assert load_domain().counts()["personas"] == 2  # load_domain() follows $ADAPT_SPEC


def test_adapt_validate_from_any_directory_uses_the_shipped_spec_or_adapt_spec(tmp_path):
    env = {**os.environ, "ADAPT_SPEC": str(SMALL)}
    r = subprocess.run([sys.executable, "-m", "adaptbench.cli", "validate"], cwd=tmp_path, capture_output=True,
                       text=True, timeout=120, env=env)
    assert r.returncode == 0 and "2 personas" in r.stdout, r.stderr


def test_spec_export_copies_the_paper_spec_for_authors(tmp_path, capsys):
    from adaptbench.cli import main

    dest = tmp_path / "myspec"
    assert main(["spec", "export", str(dest)]) == 0
    shipped = sorted(p.relative_to(paper.shipped_spec()) for p in paper.shipped_spec().rglob("*") if p.is_file())
    assert sorted(p.relative_to(dest) for p in dest.rglob("*") if p.is_file()) == shipped
    assert (dest / "splits.yaml").read_bytes() == (paper.shipped_spec() / "splits.yaml").read_bytes()
    assert f"adapt validate {dest}" in capsys.readouterr().out
    assert main(["spec", "export", str(dest)]) == 2  # never over an existing spec
    assert "not an empty directory" in capsys.readouterr().err


def test_progress_off_a_terminal_is_a_few_plain_lines(monkeypatch):
    from adaptbench import progress

    monkeypatch.setattr(progress, "NON_TTY_SECONDS", 0.0)
    out = io.StringIO()
    with progress.progress_bar(200, "rollout -> r.jsonl", stream=out) as bar:
        for i in range(200):
            bar.set_postfix_str(f"oracle juan/eggs {i}", refresh=False)
            bar.update()
    lines = out.getvalue().splitlines()
    assert "\r" not in out.getvalue() and "\x1b" not in out.getvalue()
    assert 2 <= len(lines) <= 12 and lines[-1].startswith("rollout -> r.jsonl: 100%") and "200/200" in lines[-1]
    quiet = io.StringIO()
    with progress.progress_bar(5, "x", enabled=False, stream=quiet) as bar:
        bar.update(5)
    assert quiet.getvalue() == ""
