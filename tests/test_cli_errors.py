"""Errors stay errors: every command given a spec with errors prints the located diagnostics and exits 1
(one handler in the CLI), never a traceback. Runs on a broken copy of the small test spec."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from adaptbench.cli import main

SMALL = Path(__file__).resolve().parent / "spec_small"
BROKEN = """\
id: zed
name: Zed
preferences:
  - {id: p, text: Milk, rule: "for eggs: it has mlk", topics: [milk]}
"""
LOCATED = "spec/personas/zed.yaml:4:"

COMMANDS = [
    ["validate", "spec"],
    ["test", "spec"],
    ["rollout", "--spec", "spec", "--agent", "oracle", "--seeds", "0", "--out", "runs.jsonl", "--quiet"],
    ["users", "check", "--spec", "spec"],
    ["check-solvable", "--spec", "spec", "--seeds", "0"],
    ["replay", "--spec", "spec", "--task", "eggs", "--persona", "ana", "--seed", "0", "actions.txt"],
    ["scene", "--spec", "spec"],
    ["play", "--spec", "spec", "--task", "eggs", "--persona", "ana"],
    ["grammar", "build", "--spec", "spec", "--out", "g"],
    ["grammar", "check", "--spec", "spec", "--out", "g"],
    ["grammar", "show", "--spec", "spec", "--task", "eggs", "--seed", "0"],
    ["vocab", "--spec", "spec"],
    ["new", "persona", "zoe", "--spec", "spec"],
    ["schema", "--spec", "spec", "--out", "schemas"],
]


@pytest.fixture
def broken(tmp_path, monkeypatch):
    spec = tmp_path / "spec"
    shutil.copytree(SMALL, spec)
    (spec / "personas" / "zed.yaml").write_text(BROKEN)
    (spec / "splits.yaml").write_text((spec / "splits.yaml").read_text().replace("[ben]", "[ben, zed]"))
    (tmp_path / "actions.txt").write_text("Look for eggs\n")
    monkeypatch.chdir(tmp_path)
    return spec


@pytest.mark.parametrize("argv", COMMANDS, ids=[" ".join(c[:2]) for c in COMMANDS])
def test_every_command_reports_spec_errors_and_exits_1(broken, argv, capsys):
    status = main(argv)
    out = capsys.readouterr()
    assert status == 1, out
    text = out.err + out.out
    assert f"{LOCATED}" in text and "error[D104]" in text and "did you mean 'milk'" in text
    assert "Traceback" not in text


def test_a_whole_process_prints_no_traceback(broken):
    """The same through the installed entry point, as a user runs it."""
    r = subprocess.run([sys.executable, "-m", "adaptbench.cli", "rollout", "--spec", "spec", "--agent", "oracle",
                        "--seeds", "0", "--out", "runs.jsonl", "--quiet"], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 1
    assert LOCATED in r.stderr and "Traceback" not in r.stderr
    assert "1 error(s) in spec" in r.stderr


def test_yaml_errors_carry_a_hint(broken, capsys):
    (broken / "personas" / "zed.yaml").write_text(BROKEN.replace('"for eggs: it has mlk"', "for eggs: it has milk"))
    assert main(["check-solvable", "--spec", "spec"]) == 1
    err = capsys.readouterr().err
    assert "error[S000]" in err and "must be quoted" in err


def test_eval_with_splits_reports_spec_errors(broken, capsys):
    """`adapt eval` reads the spec only for records of trained agents (they carry a `split`)."""
    import json

    rec = {"agent": "x", "persona": "ana", "task": "eggs", "seed": 0, "satisfaction_rate": 1.0, "questions": 2,
           "split": 0}
    (broken.parent / "runs.jsonl").write_text(json.dumps(rec) + "\n")
    assert main(["eval", "runs.jsonl", "--spec", "spec"]) == 1
    err = capsys.readouterr().err
    assert LOCATED in err and "error[D104]" in err and "Traceback" not in err
