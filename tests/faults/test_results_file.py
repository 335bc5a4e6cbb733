"""Results files cannot be lost or doubled: in-place tail repair, one writer, each episode once,
a full disk ends with a message and a resumable file."""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys

import pytest

from adaptbench.harness.results import ResultsError, ResultsFile, repair_tail
from adaptbench.harness.rollout import Job, rollout

from .helpers import ROOT, SPEC, adapt, keys


def _rec(seed: int, **kw) -> dict:
    return {"agent": "oracle", "persona": "juan", "task": "eggs", "seed": seed, "spec_hash": "h", **kw}


def test_torn_tail_is_truncated_in_place(tmp_path):
    path = tmp_path / "r.jsonl"
    good = "".join(json.dumps(_rec(s)) + "\n" for s in range(3))
    path.write_text(good + '{"agent": "oracle", "pers')
    inode = path.stat().st_ino
    with ResultsFile.open(path, "h") as store:
        assert store.repaired == len('{"agent": "oracle", "pers') and len(store.done) == 3
    assert path.read_text() == good and path.stat().st_ino == inode


def test_repair_of_a_file_with_no_newline_at_all(tmp_path):
    path = tmp_path / "r.jsonl"
    path.write_bytes(b"x" * 200_000)
    fd = os.open(path, os.O_RDWR)
    assert repair_tail(fd) == 200_000
    os.close(fd)
    assert path.read_bytes() == b""


def test_a_run_that_writes_nothing_leaves_no_file_it_created(tmp_path):
    new = tmp_path / "new.jsonl"
    with ResultsFile.open(new):
        assert new.exists()  # created and locked while the run lasts
    assert not new.exists()
    with ResultsFile.open(new) as store:
        store.append({"agent": "a", "persona": "p", "task": "t", "seed": 0})
    assert new.exists()
    old = tmp_path / "old.jsonl"
    old.write_text("")
    with ResultsFile.open(old):
        pass
    assert old.exists()  # the user's file, even if empty, is never removed


def test_a_second_writer_is_refused(tmp_path):
    path = tmp_path / "r.jsonl"
    with ResultsFile.open(path, "h"), pytest.raises(ResultsError, match="another run"):
        ResultsFile.open(path, "h")
    ResultsFile.open(path, "h").close()  # released on close


def test_an_episode_is_never_written_twice(tmp_path):
    path = tmp_path / "r.jsonl"
    with ResultsFile.open(path, "h") as store:
        assert store.append(_rec(0)) and not store.append(_rec(0))
    with ResultsFile.open(path, "h") as store:
        assert not store.append(_rec(0))
        assert store.append(_rec(0, agent_config={"agent": "oracle", "user": "llm"}))  # another configuration
        assert store.append(_rec(0, spec_hash="other"))  # another spec
    assert len(path.read_text().splitlines()) == 3


def test_resume_counts_only_the_same_spec(tmp_path, domain):
    path = tmp_path / "r.jsonl"
    path.write_text(json.dumps(_rec(0, persona=domain.personas[0].id, agent="never-ask", spec_hash="old")) + "\n")
    res = rollout([Job("never-ask", domain.personas[0].id, "eggs", 0)], path, spec=str(SPEC), progress=False)
    assert res.ran == 1 and res.present == 0


def test_repeated_seeds_and_personas_run_once(tmp_path, domain):
    out = tmp_path / "r.jsonl"
    p = domain.personas[0].id
    r = adapt(["rollout", "--agent", "never-ask,never-ask", "--personas", f"{p},{p}", "--tasks", "cereal",
               "--seeds", "0,0,0-1", "--out", out, "--quiet"])
    assert r.returncode == 0, r.stderr
    assert sorted(keys(out)) == [("never-ask", p, "cereal", 0), ("never-ask", p, "cereal", 1)]


def test_concurrent_writers_never_duplicate(tmp_path, domain):
    out = tmp_path / "r.jsonl"
    args = ["rollout", "--agent", "never-ask", "--personas", domain.personas[0].id, "--tasks", "all",
            "--seeds", "0-1", "--out", out, "--quiet"]
    procs = [subprocess.Popen([sys.executable, "-m", "adaptbench.cli", *map(str, args)], cwd=ROOT,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(3)]
    results = [p.communicate(timeout=120) + (p.returncode,) for p in procs]
    ok = [r for r in results if r[2] == 0]
    refused = [r for r in results if r[2] != 0]
    assert ok and all("another run" in r[1] and "Traceback" not in r[1] for r in refused)
    k = keys(out)
    assert len(k) == len(set(k))


def _fsize_limit(limit: int):
    def apply():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


def test_disk_full_ends_with_a_message_and_a_resumable_file(tmp_path, domain):
    out = tmp_path / "r.jsonl"
    args = [sys.executable, "-m", "adaptbench.cli", "rollout", "--agent", "oracle", "--personas",
            domain.personas[0].id, "--tasks", "eggs,cereal", "--seeds", "0-2", "--out", str(out), "--quiet"]
    r = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=120,
                       preexec_fn=_fsize_limit(20_000))
    assert r.returncode == 1 and "disk full" in r.stderr and "resume" in r.stderr
    assert "Traceback" not in r.stderr
    first = keys(out)  # every line complete
    r = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    k = keys(out)
    assert k[: len(first)] == first and len(k) == len(set(k)) == 6


@pytest.mark.parametrize("out, what", [(".", "is a directory"), ("README.md/x.jsonl", "parent of it is a file"),
                                       ("/proc/version", "cannot write")])
def test_bad_out_paths(out, what, domain):
    r = adapt(["rollout", "--agent", "oracle", "--personas", domain.personas[0].id, "--tasks", "eggs",
               "--seeds", "0", "--out", out, "--quiet"])
    assert r.returncode in (1, 2) and what in r.stderr and "Traceback" not in r.stderr


@pytest.mark.parametrize("seeds, what", [("3-1", "empty seed range"), ("0-99999999999", "at most"),
                                         ("x", "not a seed"), ("-1", "not a seed"), ("", "no seeds"),
                                         ("1-2-3", "not a seed")])
def test_bad_seed_ranges(seeds, what):
    r = adapt(["rollout", "--agent", "oracle", "--seeds", seeds, "--out", "/tmp/never-written.jsonl", "--quiet"])
    assert r.returncode == 2 and what in r.stderr and "Traceback" not in r.stderr
