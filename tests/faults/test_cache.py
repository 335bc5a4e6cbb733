"""The cache heals: a broken or hand-edited entry is discarded and rebuilt with a one-line warning
naming the file."""

from __future__ import annotations

import pytest

from adaptbench.compiler import load_domain, spec_hash

from ..conftest import SMALL as SPEC  # engine test: the small test spec
from .helpers import adapt


def _corrupt(path, how: str) -> None:
    data = path.read_bytes()
    if how == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif how == "edited":  # valid JSON, wrong checksum
        path.write_bytes(data.replace(b'"description":"', b'"description":"X', 1))
    elif how == "garbage":
        path.write_bytes(b"\x00\xff" * 100)
    elif how == "empty":
        path.write_bytes(b"")
    elif how == "old format":
        path.write_bytes(data.partition(b"\n")[2])


@pytest.mark.parametrize("how", ["truncated", "edited", *(pytest.param(h, marks=pytest.mark.slow)
                                                          for h in ("garbage", "empty", "old format"))])
def test_broken_cache_is_rebuilt(tmp_path, monkeypatch, capsys, small_domain, how):
    monkeypatch.setenv("ADAPT_CACHE", str(tmp_path))
    load_domain(SPEC)
    path = tmp_path / f"domain-{spec_hash([SPEC])}.json"
    _corrupt(path, how)
    capsys.readouterr()
    assert load_domain(SPEC).to_json() == small_domain.to_json()
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(path) in err and "rebuilding" in err
    assert load_domain(SPEC).to_json() == small_domain.to_json() and capsys.readouterr().err == ""  # healed


def test_broken_cache_in_a_command(tmp_path):
    env = {"ADAPT_CACHE": str(tmp_path)}
    import os

    env = {**os.environ, **env}
    assert adapt(["scene", "--seed", "0", "--spec", SPEC], env=env).returncode == 0
    path = tmp_path / f"domain-{spec_hash([SPEC])}.json"
    _corrupt(path, "truncated")
    r = adapt(["scene", "--seed", "0", "--spec", SPEC], env=env)
    assert r.returncode == 0 and str(path) in r.stderr and "Traceback" not in r.stderr
