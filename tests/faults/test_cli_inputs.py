"""Every command, every bad input: a message and an exit code, never a traceback or a hang.

Each case runs `adapt ...` as a user would (a whole process, time and memory limits) and asserts a
non-zero exit code, a message on stderr naming the problem and no traceback. A quick slice runs by
default; the whole table with `pytest -m slow tests/faults`.
"""

from __future__ import annotations

import pytest

from .helpers import adapt

BINARY = "\udcff\udcfe\x00\x01 not text"


def _files(tmp_path) -> dict:
    """Bad files to point commands at."""
    (tmp_path / "dir").mkdir()
    (tmp_path / "empty.txt").write_text("")
    (tmp_path / "binary.txt").write_bytes(b"\xff\xfe\x00\x01 not text\n")
    (tmp_path / "huge_line.txt").write_text("Look for " + "x" * 1_000_000 + "\n")
    (tmp_path / "spec_file.yaml").write_text("a: 1\n")
    (tmp_path / "empty_spec").mkdir()
    return {k: str(tmp_path / k) for k in ("dir", "empty.txt", "binary.txt", "huge_line.txt", "spec_file.yaml",
                                          "empty_spec")} | {"missing": str(tmp_path / "missing"),
                                                            "unwritable": "/proc/adaptbench/x.jsonl"}


# (id, args with {placeholders}, a word the message must contain, quick?)
CASES = [
    ("validate-missing-dir", "validate {missing}", "missing", True),
    ("validate-a-file", "validate {spec_file.yaml}", "spec_file", False),
    ("validate-empty-dir", "validate {empty_spec}", "empty_spec", False),
    ("validate-bad-format", "validate spec --format xml", "format", False),
    ("scene-negative-seed", "scene --seed -1", "seed", False),
    ("scene-word-seed", "scene --seed abc", "seed", False),
    ("scene-missing-spec", "scene --spec {missing} --seed 0", "missing", False),
    ("play-unknown-task", "play --task pancakes --persona juan", "pancakes", True),
    ("play-unknown-persona", "play --task eggs --persona zed", "zed", False),
    ("replay-missing-file", "replay --task eggs --persona juan --seed 0 {missing}", "missing", True),
    ("replay-directory", "replay --task eggs --persona juan --seed 0 {dir}", "dir", False),
    ("replay-binary", "replay --task eggs --persona juan --seed 0 {binary.txt}", "binary.txt", False),
    ("replay-unknown-task", "replay --task pancakes --persona juan --seed 0 {empty.txt}", "pancakes", False),
    ("replay-unknown-persona", "replay --task eggs --persona zed --seed 0 {empty.txt}", "zed", False),
    ("replay-zero-steps", "replay --task eggs --persona juan --seed 0 --max-steps 0 {empty.txt}", "max-steps", False),
    ("replay-negative-seed", "replay --task eggs --persona juan --seed -3 {empty.txt}", "seed", False),
    ("rollout-unknown-agent", "rollout --agent genius --seeds 0 --out {dir}/r.jsonl", "genius", True),
    ("rollout-unknown-persona", "rollout --agent oracle --personas zed --seeds 0 --out {dir}/r.jsonl", "zed", False),
    ("rollout-unknown-task", "rollout --agent oracle --tasks pancakes --seeds 0 --out {dir}/r.jsonl", "pancakes",
     False),
    ("rollout-word-seeds", "rollout --agent oracle --seeds some --out {dir}/r.jsonl", "some", False),
    ("rollout-empty-range", "rollout --agent oracle --seeds 3-1 --out {dir}/r.jsonl", "3-1", True),
    ("rollout-absurd-range", "rollout --agent oracle --seeds 0-99999999999 --out {dir}/r.jsonl", "seeds", False),
    ("rollout-zero-workers", "rollout --agent oracle --seeds 0 --workers 0 --out {dir}/r.jsonl", "workers", False),
    ("rollout-negative-workers", "rollout --agent oracle --seeds 0 --workers -2 --out {dir}/r.jsonl", "workers",
     False),
    ("rollout-out-is-dir", "rollout --agent oracle --seeds 0 --out {dir}", "dir", False),
    ("rollout-out-unwritable", "rollout --agent oracle --seeds 0 --out {unwritable}", "adaptbench", False),
    ("rollout-missing-spec", "rollout --spec {missing} --agent oracle --seeds 0 --out {dir}/r.jsonl", "missing",
     False),
    ("eval-missing", "eval {missing}", "missing", True),
    ("eval-directory", "eval {dir}", "dir", False),
    ("eval-binary", "eval {binary.txt}", "binary.txt", False),
    ("eval-empty", "eval {empty.txt}", "empty.txt", False),
    ("eval-bad-by", "eval {empty.txt} --by colour", "colour", False),
    ("users-missing-spec", "users check --spec {missing}", "missing", False),
    ("solvable-word-seeds", "check-solvable --seeds x", "x", False),
    ("solvable-unknown-persona", "check-solvable --seeds 0 --persona zed", "zed", False),
    ("grammar-show-unknown-task", "grammar show --task pancakes --seed 0", "pancakes", True),
    ("grammar-show-missing-after", "grammar show --task eggs --seed 0 --after {missing}", "missing", False),
    ("grammar-show-binary-after", "grammar show --task eggs --seed 0 --after {binary.txt}", "binary.txt", False),
    ("grammar-show-bad-level", "grammar show --task eggs --seed 0 --level loose", "level", False),
    ("grammar-build-unwritable", "grammar build --out /proc/adaptbench-grammars", "adaptbench-grammars", False),
    ("grammar-check-missing-dir", "grammar check --out {missing}", "missing", False),
    ("schema-unwritable", "schema --out /proc/adaptbench-schemas", "adaptbench-schemas", False),
]


def _run(tmp_path, args: str):
    files = _files(tmp_path)
    argv = args.split()
    for i, a in enumerate(argv):
        for k, v in files.items():
            a = a.replace("{" + k + "}", v)
        argv[i] = a
    return adapt(argv, timeout=60)


def _check(r, word: str) -> None:
    assert r.returncode not in (0, None), f"exit {r.returncode}\n{r.stdout[-500:]}\n{r.stderr[-500:]}"
    assert "Traceback" not in r.stderr and "Traceback" not in r.stdout, r.stderr[-2000:]
    assert word.lower() in (r.stderr + r.stdout).lower(), f"message does not name '{word}': {r.stderr[-800:]}"


@pytest.mark.parametrize("args,word", [pytest.param(a, w, id=i) for i, a, w, q in CASES if q])
def test_bad_input_quick(tmp_path, args, word):
    _check(_run(tmp_path, args), word)


@pytest.mark.slow
@pytest.mark.parametrize("args,word", [pytest.param(a, w, id=i) for i, a, w, q in CASES if not q])
def test_bad_input(tmp_path, args, word):
    _check(_run(tmp_path, args), word)
