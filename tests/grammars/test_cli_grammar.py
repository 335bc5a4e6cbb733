"""`adapt grammar build | check | show`."""

from __future__ import annotations

import pytest

from adaptbench.cli import main

from .conftest import ROOT


@pytest.mark.paper  # the committed grammars are those of the shipped spec
def test_check_passes_on_the_committed_grammars(capsys):
    assert main(["grammar", "check", "--spec", str(ROOT / "spec"), "--out", str(ROOT / "grammars")]) == 0
    assert "match spec/" in capsys.readouterr().out


@pytest.mark.paper  # the committed grammars are those of the shipped spec
def test_build_then_check_then_drift(tmp_path, capsys):
    out = tmp_path / "g"
    assert main(["grammar", "build", "--spec", str(ROOT / "spec"), "--out", str(out)]) == 0
    assert (out / "tasks" / "eggs.lark").read_text() == (ROOT / "grammars" / "tasks" / "eggs.lark").read_text()
    assert main(["grammar", "check", "--spec", str(ROOT / "spec"), "--out", str(out)]) == 0
    (out / "domain.lark").write_text("start: action\n")
    capsys.readouterr()
    assert main(["grammar", "check", "--spec", str(ROOT / "spec"), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "domain.lark: differs from what spec/ gives" in err and "adapt grammar build" in err


def test_show_after_actions(tmp_path, capsys):
    actions = tmp_path / "a.txt"
    actions.write_text("# explore\nLook for eggs\n")
    spec = str(ROOT / "spec")
    assert main(["grammar", "show", "--spec", spec, "--task", "eggs", "--full-scene"]) == 0
    before = capsys.readouterr().out
    assert main(["grammar", "show", "--spec", spec, "--task", "eggs", "--full-scene", "--after", str(actions)]) == 0
    after = capsys.readouterr().out
    assert '"egg_0"' in after and '"egg_0"' not in before
    assert main(["grammar", "show", "--spec", spec, "--task", "eggs", "--seed", "1", "--level", "syntax",
                 "--variant", "never_ask"]) == 0
    text = capsys.readouterr().out
    assert "NAME: /[a-z][a-z0-9_]*/" in text and "ask" not in text.split("\n")[3]


def test_show_reports_bad_input(tmp_path, capsys):
    spec = str(ROOT / "spec")
    assert main(["grammar", "show", "--spec", spec, "--task", "brunch", "--seed", "0"]) == 2
    assert "unknown task 'brunch'" in capsys.readouterr().err
    assert main(["grammar", "show", "--spec", spec, "--task", "eggs", "--seed", "0",
                 "--after", str(tmp_path / "missing.txt")]) == 2
    assert "cannot read" in capsys.readouterr().err


def test_cli_choices_match_the_grammar_levels_and_variants():
    """cli.grammar writes the choices out (so `adapt --help` does not import the grammar code)."""
    from adaptbench.cli import grammar as cli_grammar
    from adaptbench.grammars import LEVELS, VARIANTS

    assert (cli_grammar.LEVELS, cli_grammar.VARIANTS) == (LEVELS, VARIANTS)
