"""The oracle's searched plans, kept on disk: a search is ~200 private simulations of the episode (about a
second), and its result depends only on the compiled domain, the task, the persona, the scene and the
code, so the second time an episode's plan is asked for (the README's Table 1 then `adapt test spec`'s
solvability check, a teacher's data built again, a rerun of an evaluation) it is read instead.

    plan = searched(oracle)          # Oracle.search(), or the plan it found before

The key is a hash of everything the search reads: the compiled domain's full contents (not only its
spec hash, so a domain changed in memory is another key), the task and persona (their contents), the
scene seed, whether the scene is full, the search's rounds, and the source of the whole package (any
code change starts a new cache). Entries live in `compiler.cache_dir()`/oracle/<code>/ as small JSON
files, written atomically. `ADAPT_ORACLE_CACHE=0` turns the cache off; a cache that cannot be read or
written is passed over (the plan is searched), never an error.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from ..runtime.tables import IdentityLRU

_CODE: list = []  # the package source's digest, computed once per process
_DOMAINS = IdentityLRU(4)  # domain -> the digest of its contents (it holds the domain it keys)


def enabled() -> bool:
    """Whether plans are cached ($ADAPT_ORACLE_CACHE, on unless 0/off/no/false)."""
    return os.environ.get("ADAPT_ORACLE_CACHE", "1").strip().lower() not in ("0", "off", "no", "false")


def code_digest() -> str:
    """A digest of every Python source file of the package (what the search and the simulator run)."""
    if not _CODE:
        root = Path(__file__).resolve().parents[1]
        h = hashlib.sha256()
        for path in sorted(root.rglob("*.py")):
            h.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes() + b"\0")
        _CODE.append(h.hexdigest()[:16])
    return _CODE[0]


def domain_digest(domain) -> str:
    """A digest of the compiled domain's contents (its repr: frozen dataclasses, tuples and dicts in a fixed
    order, so the same in every process)."""
    return _DOMAINS.get_or_build(domain, lambda: hashlib.sha256(repr(domain).encode()).hexdigest())


def entry(oracle) -> Path:
    """The cache file of an oracle's search."""
    key = repr((domain_digest(oracle.domain), oracle.task, oracle.persona, oracle.seed, oracle.full, oracle.rounds))
    from ..compiler import cache_dir

    return cache_dir() / "oracle" / code_digest() / f"{hashlib.sha256(key.encode()).hexdigest()[:32]}.json"


def _load(path: Path):
    try:
        raw = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(raw, dict):
        return None
    return {k: tuple(v) if isinstance(v, list) else v for k, v in raw.items()}


def _store(path: Path, plan: dict) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps({k: list(v) if isinstance(v, tuple) else v for k, v in plan.items()}))
        tmp.replace(path)  # atomic: a reader sees the whole plan or none
    except OSError:
        pass


def searched(oracle) -> dict:
    """`oracle.search()`, or the plan an identical search found before (read from the cache)."""
    if not enabled():
        return oracle.search()
    path = entry(oracle)
    plan = _load(path)
    if plan is None:
        plan = oracle.search()
        _store(path, plan)
    return plan
