"""A new user's first steps, whole process: every command the README shows runs as written (from another
directory too), and each natural mistake gets one line that names it: `adapt validate spec` where no
./spec exists uses the packaged spec and says so; `adapt eval FILE --markdown` prints Markdown; an
unclosed quote is reported where it opened; a missing extra's hint fits how adaptbench was installed;
`adapt eval` on a file that is not JSONL says so; Ctrl-C while a model loads prints a line; the files the
docs' commands write in the repository root are git-ignored."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time

import pytest

from .helpers import ROOT, adapt, sigint_as_in_a_terminal

SMALL = ROOT / "tests" / "spec_small"


def test_validate_spec_from_another_directory_uses_the_packaged_spec(tmp_path):
    got = adapt(["validate", "spec"], cwd=tmp_path)
    assert got.returncode == 0, got.stderr
    assert got.stdout.startswith("ok: ") and "error" not in got.stderr
    assert "no directory 'spec' here; using the paper's spec shipped with adaptbench" in got.stderr
    other = adapt(["validate", "specs"], cwd=tmp_path)  # any other missing path stays an error
    assert other.returncode == 1 and "specs:1:1: error[S003]: spec directory not found" in other.stderr


def test_eval_markdown_without_a_path_prints_markdown(tmp_path):
    runs = tmp_path / "r.jsonl"
    assert adapt(["rollout", "--agent", "oracle", "--personas", "juan", "--tasks", "eggs", "--seeds", "0",
                  "--out", runs, "--quiet"]).returncode == 0
    got = adapt(["eval", runs, "--markdown"], cwd=tmp_path)
    assert got.returncode == 0, got.stderr
    assert got.stdout.startswith("**Table 1**\n\n| Paper row | Method |") and "**Table 2**" in got.stdout
    assert "| teacher | oracle | 1 | 50 | 100.0% ± 0.0% |" in got.stdout
    assert [p.name for p in tmp_path.iterdir()] == ["r.jsonl"]  # nothing written: no file named '-'
    to_file = adapt(["eval", runs, "--markdown", tmp_path / "t.md"])
    assert to_file.returncode == 0 and "| Paper row |" not in to_file.stdout
    assert (tmp_path / "t.md").read_text().startswith("**Table 1**")


def test_an_unclosed_quote_is_reported_where_it_opened(tmp_path):
    spec = tmp_path / "spec"
    shutil.copytree(SMALL, spec)
    persona = next(iter(sorted((spec / "personas").glob("*.yaml"))))
    lines = persona.read_text().splitlines(keepends=True)
    key = lines[2].split(":")[0]
    lines[2] = f'{key}: "Ana\n'  # line 3: a quote opened, never closed
    persona.write_text("".join(lines))
    got = adapt(["validate", spec])
    assert got.returncode == 1
    first = got.stderr.splitlines()[0]
    col = len(key) + 3
    assert f"personas/{persona.name}:3:{col}: error[S000]: YAML syntax error: the quoted value opened here is " \
           "not closed" in first, first
    assert "indentation" not in first


def _without_torch(args: list, editable: bool) -> subprocess.CompletedProcess:
    code = ("import sys; sys.modules['torch'] = None; import adaptbench.install as i; "
            f"i.editable = lambda: {editable}; from adaptbench.cli.main import main; sys.exit(main(sys.argv[1:]))")
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=60, cwd=ROOT)


@pytest.mark.parametrize(("editable", "hint"), [
    (True, f"pip install torch==2.13.0 && pip install -e '{ROOT}[models]'"),
    (False, "pip install torch==2.13.0 && pip install 'adaptbench[models]'"),
])
def test_the_missing_torch_hint_fits_the_install(tmp_path, editable, hint):
    got = _without_torch(["model", "init", "--out", str(tmp_path / "m")], editable)
    assert got.returncode != 0 and "Traceback" not in got.stderr
    assert got.stderr.rstrip().endswith(hint), got.stderr
    assert (" -e " in got.stderr) == editable


def test_eval_on_a_file_that_is_not_jsonl_says_so():
    got = adapt(["eval", "README.md"])
    assert got.returncode == 2
    assert "README.md is not a run record (JSONL written by adapt rollout)" in got.stderr
    assert "torn" not in got.stderr and got.stderr.count("\n") == 1


def test_ctrl_c_while_a_model_loads_prints_a_line():
    """Ctrl-C while `adapt rollout --agent planner` prepares its model (held there: the test waits for it, then
    interrupts; no command catches it so early)."""
    code = ("import faulthandler, signal, sys, time, adaptbench.llm.named as n\n"
            "faulthandler.register(signal.SIGUSR1)\n"  # a hang prints where it is (below)
            "def slow(*a, **k):\n"
            "    print('loading', file=sys.stderr, flush=True); time.sleep(60)\n"
            "n.resolve_model = slow\n"
            "from adaptbench.cli.main import main; sys.exit(main(sys.argv[1:]))")
    p = subprocess.Popen([sys.executable, "-c", code, "rollout", "--agent", "planner", "--model", "student",
                          "--personas", "juan", "--tasks", "eggs", "--out", os.devnull], cwd=ROOT,
                         stderr=subprocess.PIPE, text=True, preexec_fn=sigint_as_in_a_terminal)
    try:
        assert p.stderr.readline().strip() == "loading"
        time.sleep(0.2)
        p.send_signal(signal.SIGINT)
        try:
            err = p.communicate(timeout=20)[1]
        except subprocess.TimeoutExpired:
            p.send_signal(signal.SIGUSR1)  # the child's threads' stacks, for the failure message
            time.sleep(1)
            p.kill()
            pytest.fail("no exit within 20 s of SIGINT; the child's stacks:\n" + p.communicate()[1][-4000:])
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130
    assert err.strip() == "adapt: interrupted (Ctrl-C) before the command finished" and "Traceback" not in err


DOC_OUTPUTS = ["r.jsonl", "table.md", "tables.md", "table.csv", "table.png", "t.png", "report.html", "myspec/x",
               "teach/oracle.jsonl", "eval/dpo.jsonl", "smol-data/pairs.jsonl", "runs/demo.jsonl", "models/tiny/x"]


@pytest.mark.skipif(not (ROOT / ".git").exists() or shutil.which("git") is None, reason="not a git checkout")
def test_files_the_docs_commands_write_in_the_root_are_ignored():
    got = subprocess.run(["git", "check-ignore", "--no-index", *DOC_OUTPUTS], cwd=ROOT, capture_output=True, text=True)
    assert sorted(got.stdout.split()) == sorted(DOC_OUTPUTS)
    kept = subprocess.run(["git", "check-ignore", "--no-index", "README.md", "pyproject.toml", "docs/x.md"], cwd=ROOT,
                          capture_output=True, text=True)
    assert kept.stdout == ""  # the repository's own files are not
