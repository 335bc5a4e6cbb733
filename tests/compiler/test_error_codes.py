"""Every diagnostic code documented in docs/errors.md is triggered by a case in tests/compiler/codes/, on the
small test spec (tests/spec_small), in well under a second each.

A case is one YAML file, named after the code it shows:

    codes: [D104]                 # codes the compile must report (others may come along)
    message: did you mean 'milk'  # optional: text one of those diagnostics must contain
    files:                        # files written into a copy of tests/spec_small (replacing any)
      personas/zed.yaml: |
        ...
    latin1: {...}                 # the same, written as Latin-1 (for encoding errors)
    replace:                      # optional: edits of files of the copy, [old, new] each
      tasks/recipes.yaml: [["default: butter", "default: lard"]]
    delete: [engine.yaml]         # optional: files of the copy to remove
    mkdir: [empty]                # optional: directories to create next to the copy
    dirs: [spec, other]           # optional: the directories compiled (default: [spec])

A code added to docs/errors.md needs a case here; the test below names the codes that have none.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
import yaml

from adaptbench.compiler import compile_spec

from ..timing import own_cpu_seconds

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
SMALL = ROOT / "tests" / "spec_small"
CASES = sorted((HERE / "codes").glob("*.yaml"))


def documented_codes() -> set:
    """The codes in the first column of docs/errors.md's tables."""
    return set(re.findall(r"^\|\s*([A-Z][A-Z0-9]?\d{3})\s*\|", (ROOT / "docs" / "errors.md").read_text(), re.M))


def build_case(case: dict, tmp: Path) -> list:
    """Write the case's spec under `tmp`; return the directories to compile."""
    spec = tmp / "spec"
    shutil.copytree(SMALL, spec, ignore=shutil.ignore_patterns("fixtures"))
    for enc, key in (("utf-8", "files"), ("latin-1", "latin1")):
        for rel, text in (case.get(key) or {}).items():
            (spec / rel).parent.mkdir(parents=True, exist_ok=True)
            (spec / rel).write_bytes(text.encode(enc))
    for rel in case.get("delete") or ():
        (spec / rel).unlink()
    for rel in case.get("mkdir") or ():
        (tmp / rel).mkdir(parents=True)
    for rel, edits in (case.get("replace") or {}).items():
        text = (spec / rel).read_text()
        for old, new in edits:
            assert old in text, f"replace: '{old}' is not in {rel}"
            text = text.replace(old, new, 1)
        (spec / rel).write_text(text)
    return [tmp / d for d in case.get("dirs", ["spec"])]


@pytest.fixture(scope="module")
def warm():
    """Compile the small spec once, so the rule parser is built before any case is timed."""
    compile_spec([SMALL])


@pytest.mark.parametrize("path", CASES, ids=[p.stem for p in CASES])
def test_case_reports_its_codes(path, tmp_path, warm):
    case = yaml.safe_load(path.read_text())
    dirs = build_case(case, tmp_path)
    with own_cpu_seconds() as took:  # the compiler's own CPU: a loaded machine's neighbours do not count
        _, diags = compile_spec(dirs)
    got = {d.code for d in diags}
    missing = set(case["codes"]) - got
    assert not missing, f"{path.name}: expected {sorted(missing)}, got: " + "; ".join(d.render() for d in diags)
    if case.get("message"):
        texts = [d.message for d in diags if d.code in case["codes"]]
        assert any(case["message"] in t for t in texts), f"{path.name}: no message contains {case['message']!r}: {texts}"
    # a blow-up (an alias bomb expanded) takes far longer; ~1 s is normal here, so 3 s leaves machines' 2-3x spread
    assert took() < 3.0, f"{path.name}: compiling the small spec took {took():.2f} s of CPU"


def test_every_documented_code_has_a_case():
    covered = {c for p in CASES for c in yaml.safe_load(p.read_text())["codes"]}
    missing = sorted(documented_codes() - covered)
    assert not missing, f"codes in docs/errors.md without a case in tests/compiler/codes/: {', '.join(missing)}"


def test_the_small_spec_is_clean():
    """The base of every case compiles without a diagnostic, so each case shows only its own codes."""
    domain, diags = compile_spec([SMALL])
    assert domain is not None and not diags, "; ".join(d.render() for d in diags)
