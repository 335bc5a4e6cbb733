"""Per-domain tables: built once per CompiledDomain and kept with it, bounded, and never shared
between domains (no module caches keyed by `id()`)."""

from __future__ import annotations

import re
from pathlib import Path

from adaptbench.compiler.model import CompiledDomain
from adaptbench.compiler.rules import parse_rule
from adaptbench.runtime.index import runtime_index
from adaptbench.runtime.scene import sample_scene
from adaptbench.runtime.tables import LRU, IdentityLRU, domain_tables

SRC = Path(__file__).resolve().parents[2] / "src" / "adaptbench"


def test_lru_keeps_the_most_recent_within_its_bound():
    lru = LRU(2)
    lru.put("a", 1)
    lru.put("b", 2)
    assert lru.get("a") == 1  # a is now the most recent
    lru.put("c", 3)
    assert len(lru) == 2 and lru.get("b") is None and lru.get("a") == 1 and lru.get("c") == 3
    assert lru.get_or_build("d", lambda: 4) == 4 and len(lru) == 2


def test_identity_lru_tells_equal_objects_apart_and_holds_what_it_keys():
    lru = IdentityLRU(8)
    r1, r2 = parse_rule("it has milk"), parse_rule("it has milk")
    assert r1 == r2 and r1 is not r2
    assert lru.get_or_build(r1, lambda: "one") == "one"
    assert lru.get_or_build(r2, lambda: "two") == "two"
    assert lru.get_or_build(r1, lambda: "again") == "one"
    assert lru.get_or_build(r1, lambda: "cond", "cond") == "cond"  # the extra key is part of the key


def test_tables_live_with_their_domain_and_are_not_shared(domain):
    twin = CompiledDomain.from_json(domain.to_json())
    assert domain_tables(domain) is domain_tables(domain)
    assert domain_tables(twin) is not domain_tables(domain)
    assert runtime_index(domain).tables is domain_tables(domain)
    a, b = sample_scene(domain, 7), sample_scene(twin, 7)
    assert a is sample_scene(domain, 7) and a is not b and a == b
    assert domain_tables(domain).scenes.maxsize and domain_tables(domain).world_templates.maxsize


def test_no_module_cache_keyed_by_id():
    hits = []
    for path in SRC.rglob("*.py"):
        if path.name == "tables.py":  # IdentityLRU: bounded, per domain, and it holds what it keys
            continue
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if re.search(r"\[id\(|\(id\(|\.get\(id\(", line):
                hits.append(f"{path.relative_to(SRC)}:{n}: {line.strip()}")
    assert hits == []
