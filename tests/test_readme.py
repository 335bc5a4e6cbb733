"""The README's Python example runs from an empty directory and prints exactly what the README shows."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "spec"  # a paper test: the example loads the shipped spec


def test_readme_python_example_prints_what_the_readme_says(tmp_path):
    sys.path.insert(0, str(ROOT / ".ci"))
    try:
        from readme_example import blocks
    finally:
        sys.path.pop(0)
    code, expected = blocks()
    assert "import adaptbench\n" in code and "from adaptbench." not in code  # one import
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout == expected
    assert list(tmp_path.iterdir()) == []  # nothing written to the working directory


def test_import_adaptbench_is_lazy_and_every_public_name_resolves():
    code = ("import sys, adaptbench; before = sorted(m for m in sys.modules if m.startswith('adaptbench.')); "
            "[getattr(adaptbench, n) for n in adaptbench.__all__]; "
            "print(before, len(adaptbench.__all__))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    before, n = r.stdout.rsplit(" ", 1)
    assert before == "[]" and int(n) > 15  # nothing imported until used
    import adaptbench

    assert set(adaptbench.__all__) <= set(dir(adaptbench))
    try:
        adaptbench.no_such_name  # noqa: B018
    except AttributeError as exc:
        assert "no_such_name" in str(exc)
    else:
        raise AssertionError("an unknown name must raise AttributeError")


def _extras():
    import tomllib

    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]


def _names(reqs):
    import re

    return {re.split(r"[<>=\[ ;]", r, maxsplit=1)[0].lower() for r in reqs}


def test_extras_match_what_each_command_needs():
    extras = _extras()
    models, train = _names(extras["models"]), _names(extras["train"])
    assert {"torch", "transformers", "tokenizers", "llguidance"} <= models  # agents
    assert not models & {"trl", "peft", "datasets", "pandas", "pyarrow"}  # only training needs those
    assert {"adaptbench", "trl", "peft", "datasets"} <= train  # training = models + TRL, PEFT, datasets


def test_readme_command_2_names_cpu_torch_and_ci_installs_what_it_does():
    readme = (ROOT / "README.md").read_text()
    start = readme.index("# 2. install and run the tests")
    block = readme[start:readme.index("```", start)]
    comment = "".join(line for line in block.splitlines() if line.startswith("#"))
    assert "pip install torch==2.13.0" in comment  # the CPU build, before models pulls CUDA torch
    install = next(line for line in block.splitlines() if line.startswith("pip install -e"))
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    ci_install = next(line for line in ci if line.startswith("pip install -e") and "pytest" in line)
    assert install == ci_install  # CI runs the README's command 2, install and test command alike
    for extra in ("dev", "models", "serve", "train"):  # everything the tests import is installed
        assert extra in install.split('"')[1]


def test_readme_table_has_every_column_adapt_eval_prints():
    """The README's results table is `adapt eval --markdown` output: the paper-row column, every column,
    pass^1 and pass^4 and question precision included, and the line that says which k."""
    from adaptbench.harness.evaluate import header

    readme = (ROOT / "README.md").read_text()
    assert "| " + " | ".join(["Paper row", *header((1, 4))]) + " |" in readme
    assert "k=4 is the most seeds every (method, persona," in readme
    assert "docs/evaluation.md" in readme


def test_readme_command_1_is_what_ci_runs_and_prints_the_table_under_it():
    """Command 1 runs the seeds the results table is for (0-3: the pass^4 column), CI runs it as written and
    compares the Table 1 it prints with the README's (.ci/readme_table.py)."""
    readme = (ROOT / "README.md").read_text()
    start = readme.index("# 1. install and run the main job")
    command = next(line for line in readme[start:].splitlines() if line.startswith("pip install -e ."))
    job = command.split(" && ", 1)[1]
    assert "--seeds 0-3" in job and "--out runs/demo.jsonl" in job
    ci = (ROOT / ".ci" / "run").read_text()
    assert job.replace("adapt validate spec && ", "adapt validate spec && adapt grammar check && ") in ci
    assert "adapt eval runs/demo.jsonl --markdown | python .ci/readme_table.py" in ci
    assert "Scripted agents on all 16 personas x 8 tasks x scene seeds 0-3" in readme
    assert "`adapt eval runs/demo.jsonl --markdown`" in readme  # the caption's command, runnable as written
    sys.path.insert(0, str(ROOT / ".ci"))
    try:
        from readme_table import readme_table
    finally:
        sys.path.pop(0)
    rows = readme_table()
    assert len(rows) == 9 and all("| 512 |" in r for r in rows if "missing" not in r and "---" not in r
                                  and "Paper row" not in r)  # 128 (persona, task) pairs x 4 seeds


def test_readme_command_2_names_what_the_viewer_tests_need():
    readme = (ROOT / "README.md").read_text()
    start = readme.index("# 2. install and run the tests")
    comment = " ".join(line for line in readme[start:readme.index("```", start)].splitlines() if line.startswith("#"))
    assert "Chromium" in comment and "apt-get install chromium" in comment
    assert "ADAPT_REQUIRE_CHROMIUM=1" in (ROOT / ".ci" / "run").read_text()  # CI installs it: there they must run
    import tomllib

    addopts = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]["addopts"]
    assert "-rs" in addopts.split()  # every skip's reason in the summary
