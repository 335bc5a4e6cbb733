"""A kitchen that behaves like one (issue 6, item 10): opening shows what is inside, `Look for` finds
appliances and furniture, pouring needs something to pour into, and printed ids can be named next."""

from __future__ import annotations

import re

from .helpers import run, setup_ok


def test_opening_a_cabinet_reveals_its_contents(domain):
    r, env = setup_ok(domain, [], "Open cabinet_3")
    assert r.ok and "Opened cabinet_3." in r.observation and "pot_0" in r.observation
    assert "pot_0" in env.world.known
    r2, _ = setup_ok(domain, ["Open cabinet_3"], "Move pot_0 to stove_0")
    assert r2.ok, r2.observation


def test_look_for_finds_appliances_and_furniture(domain):
    r, _ = setup_ok(domain, [], "Look for kettle")
    assert r.ok and "kettle_0" in r.observation


def test_pouring_onto_a_table_fails_with_a_reason(domain):
    r, _ = setup_ok(domain, ["Look for milk"], "Pour whole_milk from milk_0 into table_0")
    assert not r.ok and "not something to pour into" in r.observation
    ok, _ = setup_ok(domain, ["Look for milk", "Look for mug"], "Pour whole_milk from milk_0 into mug_0")
    assert ok.ok, ok.observation


def test_every_printed_id_can_be_named_next(domain):
    env, results = run(domain, ["Open cabinet_3", "Open fridge_0", "Look for eggs", "Look for kettle", "Search counter_0"])
    for r in results:
        for eid in re.findall(r"\b([a-z][a-z_]*_\d+)\b", r.observation):
            assert eid in env.world.known, f"{eid} printed in {r.observation!r} but not known"
