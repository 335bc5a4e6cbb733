"""The emitted grammars: deterministic bytes, golden files, incremental = rebuilt, the two writing rules,
levels and variants, and the keyword/verb collisions."""

from __future__ import annotations

import re

import pytest

from adaptbench.grammars import GrammarCache, StateGrammar, build_base, build_index
from adaptbench.grammars.files import drift, expected_files
from adaptbench.grammars.parse import lark_parser, parse
from adaptbench.runtime.env import Env

from .conftest import ROOT, read_example


def test_emitting_twice_gives_identical_bytes(domain):
    a = expected_files(domain, build_index(domain))
    b = expected_files(domain, build_index(domain))
    assert a == b
    assert {"domain.lark", "syntax.lark"} | {f"tasks/{t.id}.lark" for t in domain.tasks} == set(a)


def test_committed_grammars_equal_a_fresh_emission(domain, index):
    """Golden: grammars/ changes only through `adapt grammar build`."""
    assert drift(ROOT / "grammars", expected_files(domain, index)) == []


def test_drift_names_the_file(domain, index, tmp_path):
    files = expected_files(domain, index)
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    (tmp_path / "tasks" / "eggs.lark").write_text("start: action\n")
    (tmp_path / "old.lark").write_text("x")
    got = {(p.name, what) for p, what in drift(tmp_path, files)}
    assert got == {("eggs.lark", "differs from what spec/ gives"), ("old.lark", "not generated from spec/ (stale)")}


@pytest.mark.parametrize("level", ["syntax", "observed", "typed"])
@pytest.mark.parametrize("variant", ["default", "never_ask", "ask_only"])
def test_incremental_update_equals_a_rebuild(domain, index, level, variant):
    env = Env(domain, "eggs", full_scene=True, seed=None)
    env.reset()
    cache = GrammarCache(index)
    g = cache.state("eggs", env.observed(), level, variant)
    for text in read_example("fifty_steps.txt"):
        env.step(text)
        assert g.update(env.observed()) == StateGrammar(build_base(index, level, variant), env.observed()).text


def test_the_base_is_cached_per_task_level_variant(index):
    cache = GrammarCache(index)
    assert cache.base("eggs") is cache.base("eggs")
    assert cache.base("eggs", "typed") is not cache.base("eggs")


def test_every_space_is_its_own_piece_and_free_text_is_unbounded(index):
    text = StateGrammar(build_base(index, "typed"), _first(index)).text
    rules = [ln for ln in text.splitlines() if re.match(r"^[a-z_]+: |^    \| ", ln)]
    assert len(rules) > 15
    for ln in rules:  # literals inside action forms: words or a single space, never "Move "
        for lit in re.findall(r'"((?:[^"\\]|\\.)*)"', ln):
            assert lit == " " or " " not in lit, ln
    regexes = re.findall(r"/((?:[^/\\]|\\.)+)/", text)
    assert regexes and not any(re.search(r"\{\d*,?\d*\}", r) for r in regexes)


def _first(index):
    from adaptbench.grammars import Observed

    return Observed(frozenset(index.layout), frozenset(index.layout_contents))


@pytest.fixture(scope="module")
def parsers(index):
    from adaptbench.grammars import Observed

    obs = Observed(frozenset(index.layout) | {"pan_0", "egg_0"}, frozenset(index.layout_contents) | {"whole_milk"})
    return {(lv, va): lark_parser(StateGrammar(build_base(index, lv, va), obs).text)
            for lv, va in (("syntax", "default"), ("observed", "default"), ("typed", "default"),
                           ("observed", "never_ask"), ("observed", "ask_only"))}


@pytest.mark.parametrize("text, action", [
    ("Chop egg_0 to get chopped_egg", "chop"), ("chop egg_0 to get chopped_egg", "chop"),
    ("chop the object egg_0 to get x", "freeform_object"), ("dice egg_0 to get x", "freeform_object"),
    ("Heat pan_0", "heat"), ("heat pan_0 to get x", "freeform_object"), ("Heat pan_0 to get x", "freeform_object"),
    ("Mix all items in pan_0 to get x", "mix"), ("mix items in pan_0 to get x", "freeform_items"),
    ("Serve the object pan_0 at table_0", "move"), ("serve the object egg_0 to get x", "freeform_object"),
    ("Serve egg_0 to get x", "freeform_object"),
])
def test_keyword_verb_collisions_are_resolved_explicitly(index, parsers, text, action):
    got = parse(parsers["observed", "default"], index, text)
    assert got is not None and got.action == action
    assert index.collisions == (("chop", "chop"),)


@pytest.mark.parametrize("text, accepted", [
    ("Search cabinet_9", {"syntax"}),  # not observed: only the syntax level names it
    ("Search whole_milk", {"syntax", "observed"}),  # a content in an entity slot: not typed
    ("Pour whole_milk from pan_0 to pan_0", {"syntax", "observed", "typed"}),
    ("Pour pan_0 from pan_0 to pan_0", {"syntax", "observed"}),
    ("Move egg_0 to pan_0", {"syntax", "observed", "typed"}),
    ("Look for eggs", {"syntax", "observed", "typed"}),
    ("Look for zzyzx", {"syntax"}),
    ("Move  egg_0 to pan_0", set()), ("move egg_0 to pan_0", set()), ("Declare Done ", set()),
])
def test_levels(index, parsers, text, accepted):
    got = {lv for lv in ("syntax", "observed", "typed") if parse(parsers[lv, "default"], index, text)}
    assert got == accepted


def test_variants(index, parsers):
    ask, move = 'Ask "Scrambled or fried?"', "Move egg_0 to pan_0"
    assert parse(parsers["observed", "default"], index, ask) and parse(parsers["observed", "default"], index, move)
    assert parse(parsers["observed", "never_ask"], index, ask) is None
    assert parse(parsers["observed", "never_ask"], index, move)
    assert parse(parsers["observed", "ask_only"], index, ask)
    assert parse(parsers["observed", "ask_only"], index, move) is None
