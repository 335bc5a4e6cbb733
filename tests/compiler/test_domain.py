"""The shipped spec compiles clean, with the counts the paper asks for, and caches."""

from __future__ import annotations

import time

from adaptbench.compiler import CompiledDomain, compile_spec, load_domain, spec_hash

from ..conftest import SPEC


def test_shipped_spec_is_clean_and_complete(domain):
    c = domain.counts()
    assert c["rooms"] == 6
    assert c["furniture"] >= 37
    assert c["movables"] >= 232
    assert c["tasks"] == 8
    assert c["verbs"] >= 82
    assert len({e.id for e in domain.entities}) == len(domain.entities)


def test_no_warnings_or_errors_on_shipped_spec():
    domain, diags = compile_spec([SPEC])
    assert domain is not None
    assert [d.render() for d in diags if d.severity == "error"] == []


def test_task_ids_and_texts_follow_the_paper(domain):
    assert [t.id for t in domain.tasks] == ["eggs", "omelette", "cereal", "toast_coffee", "parfait", "tea_eggs",
                                            "cereal_coffee", "tea_toast"]
    assert domain.task["toast_coffee"].text == "Make toast and coffee for breakfast"
    assert domain.task["tea_eggs"].components == ("tea", "eggs")


def test_release_duplicates_have_their_own_ids(domain):
    e = domain.entity
    assert e["bowl_8"].description == "small steel bowl"
    assert any(x.description.startswith("fancy porcelain china bowl") for x in domain.entities if x.id != "bowl_8")
    assert e["chair_0"].location == "dining_room"
    assert e["recliner_0"].location == "living_room"
    assert e["potato_0"].description == "golden potato"
    assert any(x.description == "sweet potato" for x in domain.entities)


def test_every_content_is_a_declared_substance(domain):
    for e in domain.entities:
        for c in e.contents:
            assert c in domain.substance


def test_json_round_trip_is_identical(domain):
    again = CompiledDomain.from_json(domain.to_json())
    assert again.to_json() == domain.to_json()
    assert again.entity["milk_0"] == domain.entity["milk_0"]


def test_cache_is_used_and_keyed_by_content(tmp_path, monkeypatch):
    monkeypatch.setenv("ADAPT_CACHE", str(tmp_path))
    first = load_domain(SPEC)
    files = list(tmp_path.glob("domain-*.json"))
    assert [f.name for f in files] == [f"domain-{spec_hash([SPEC])}.json"]
    t = time.perf_counter()
    second = load_domain(SPEC)
    assert time.perf_counter() - t < 0.5
    assert second.spec_hash == first.spec_hash and second.counts() == first.counts()
