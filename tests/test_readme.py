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
