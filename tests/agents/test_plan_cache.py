"""`agents.plan_cache`: the oracle's searched plans kept on disk, read back only for the identical search
(same domain contents, task, persona, scene and code), never an error when the cache is unusable."""

from __future__ import annotations

import dataclasses

import pytest

from adaptbench.agents import plan_cache
from adaptbench.agents.scripted import Oracle, play
from adaptbench.runtime.env import Env


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("ADAPT_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("ADAPT_ORACLE_CACHE", "1")
    return tmp_path / "cache" / "oracle"


def _episode(domain, persona="juan", task="toast_coffee", seed=0):
    env = Env(domain, task=task, persona=persona, seed=seed)
    env.reset()
    play("oracle", env)
    return [e.text for e in env.world.trace], env.evaluate().satisfied


def _no_search(monkeypatch):
    def refuse(self):
        raise AssertionError("searched again")

    monkeypatch.setattr(Oracle, "search", refuse)


def test_the_second_identical_episode_reads_the_plan_and_acts_the_same(domain, cache, monkeypatch):
    first = _episode(domain)
    assert len(list(cache.rglob("*.json"))) == 1
    _no_search(monkeypatch)
    assert _episode(domain) == first


def test_another_persona_seed_task_or_domain_content_is_searched_again(domain, cache):
    _episode(domain)
    _episode(domain, persona="leila")
    _episode(domain, seed=1)
    _episode(domain, task="eggs")
    changed = dataclasses.replace(domain, recipes=tuple(r for r in domain.recipes if r.id != "toast"))
    _episode(changed)  # same spec hash, other contents
    assert len(list(cache.rglob("*.json"))) == 5


def test_the_cache_turned_off_writes_nothing(domain, cache, monkeypatch):
    monkeypatch.setenv("ADAPT_ORACLE_CACHE", "0")
    _episode(domain)
    assert not cache.exists()


def test_a_damaged_entry_is_searched_again_and_rewritten(domain, cache):
    first = _episode(domain)
    (entry,) = cache.rglob("*.json")
    entry.write_text("{not json")
    assert _episode(domain) == first
    assert entry.read_text().startswith("{\"")


def test_an_unwritable_cache_is_passed_over(domain, tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("a file where the cache directory would be")
    monkeypatch.setenv("ADAPT_CACHE", str(blocker))
    monkeypatch.setenv("ADAPT_ORACLE_CACHE", "1")
    assert _episode(domain)[1] >= 0  # played, nothing cached


def test_the_key_covers_the_code(domain, cache, monkeypatch):
    _episode(domain)
    monkeypatch.setattr(plan_cache, "_CODE", ["other-code"])
    _episode(domain)
    assert len({p.parent.name for p in cache.rglob("*.json")}) == 2
