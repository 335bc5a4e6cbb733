"""The spec fuzzer: hostile variants of the shipped spec give a located diagnostic and exit 1, never a
hang, a traceback, a crash or unbounded memory. Every variant runs `adapt validate` in a subprocess
under a time and memory limit (slow: `pytest -m slow tests/faults`); the quick slice runs the YAML-level
variants in-process and a few of each kind through the command."""

from __future__ import annotations

import re
import time

import pytest

from adaptbench.compiler.loader import load_file, validate_schema

from ..timing import own_cpu_seconds
from .helpers import SPEC, adapt
from .hostile import HOSTILE, VARIANTS, make_spec

TIME_BUDGET = 30  # seconds per command, process start included
LOCATED = re.compile(r"^\S+:\d+:\d+: error\[[A-Z]\d{3}\]: ", re.M)
QUICK = {"cycle of two", "flow nesting 100000", "alias bomb 9x9", "rule nested 500 deep", "broken brace in success",
         "id with a trailing newline", "latin-1 byte in actions", "huge integer 5000 digits",
         "huge count in a rule 5000 digits", "huge split id"}


def _check(spec, expected: str) -> None:
    t = time.monotonic()
    r = adapt(["validate", spec], timeout=TIME_BUDGET)
    assert time.monotonic() - t < TIME_BUDGET
    assert r.returncode == 1, (r.returncode, r.stdout[-500:], r.stderr[-2000:])
    assert "Traceback" not in r.stderr and "Traceback" not in r.stdout
    assert LOCATED.search(r.stderr), r.stderr[-2000:]
    assert re.search(expected, r.stderr), r.stderr[-2000:]


def test_at_least_60_variants():
    assert len(VARIANTS) >= 60 and len({v[0] for v in VARIANTS}) == len(VARIANTS)


@pytest.mark.parametrize("name, edits, expected", [v for v in VARIANTS if v[0] in QUICK],
                         ids=[v[0] for v in VARIANTS if v[0] in QUICK])
def test_hostile_spec_quick(tmp_path, name, edits, expected):
    _check(make_spec(SPEC, tmp_path / "spec", edits), expected)


@pytest.mark.slow
@pytest.mark.parametrize("name, edits, expected", VARIANTS, ids=[v[0] for v in VARIANTS])
def test_hostile_spec(tmp_path, name, edits, expected):
    _check(make_spec(SPEC, tmp_path / "spec", edits), expected)


_RAW = [v for v in VARIANTS if list(v[1]) == [HOSTILE] and "cycle" not in v[0] and "location" not in v[0]]


@pytest.mark.parametrize("name, edits, expected", _RAW, ids=[v[0] for v in _RAW])
def test_hostile_yaml_in_process(tmp_path, name, edits, expected):
    """YAML-level variants, straight through the loader (bounded before anything recursive runs)."""
    path = tmp_path / "h.yaml"
    path.write_bytes(edits[HOSTILE])
    with own_cpu_seconds() as took:  # the loader's own CPU (0.3 s here; 5.9 s of wall clock once under load)
        doc, diags = load_file(path, "h.yaml")
        if doc is not None:
            diags = diags + validate_schema(doc, "objects")
    assert took() < 5
    text = "\n".join(d.render() for d in diags)
    assert diags and re.search(expected, text + " error"), text
