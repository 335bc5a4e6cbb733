"""Every example action the paper shows runs in the simulator (with this catalogue's ids)."""

from __future__ import annotations

import pytest

from .helpers import setup_ok

FIND = ["Look for eggs", "Look for bowl", "Look for pan", "Look for milk", "Look for apple", "Look for mug",
        "Look for coffee", "Look for tomato", "Look for onion", "Look for plate"]

EXAMPLES = [
    # paper planner prompt examples, adapted to real ids
    ([], "Open cabinet_0"),
    ([], "Close cabinet_0"),
    (FIND + ["Move pan_0 to stove_0", "Move egg_0 to pan_0"], "Heat pan_0"),
    ([], "Turn on stove_0"),
    ([], "Turn off stove_0"),
    ([], "Search counter_0"),
    ([], "Look for apple"),
    (FIND, "Place plate_0 on table_0"),
    (FIND, "Move plate_0 to table_0"),
    (FIND + ["Move egg_0 to bowl_0"], "Mix all items in bowl_0 to get cake_batter"),
    (FIND + ["Move pan_0 to stove_0", "Move egg_0 to pan_0"], "Cook items in pan_0 to get scrambled_eggs"),
    (FIND + ["Move apple_0 to counter_0"], "Chop apple_0 to get chopped_apple"),
    (FIND, "Pour whole_milk from milk_0 to mug_0"),
    (FIND, "Move apple_0 from counter_1 to bowl_1"),
    (FIND + ["Move pan_0 to stove_0", "Move egg_0 to pan_0", "Pour whole_milk from milk_0 to pan_0"],
     "whisk items in pan_0 to get custard"),
    (FIND, "brew coffee_grounds to get brewed_coffee"),
    (FIND + ["Move tomato_1 to counter_0"], "chop the object tomato_1 to get finely_chopped_tomato"),
    (FIND + ["Move onion_0 to counter_0"], "chop the object onion_0 to get sliced_onion"),
    (FIND, "crack the object egg_4 to get cracked_egg"),
    ([], 'Ask "Would you like the eggs sunny-side-up or scrambled?"'),
    ([], "Declare Done"),
    # the paper's table forms
    (FIND, "Serve the object plate_0 at table_0"),
    (FIND, "Place the object plate_0 at table_1"),
    (FIND, "Pour whole_milk from milk_0 into mug_0"),
    (FIND + ["Move egg_0 to bowl_0"], "beat items in bowl_0 to get egg_mix"),
    (FIND, "peel the object apple_0 to get peeled_apple"),
]


@pytest.mark.parametrize("setup,action", EXAMPLES, ids=[e[1] for e in EXAMPLES])
def test_paper_example_runs(domain, setup, action):
    result, _ = setup_ok(domain, setup, action)
    assert result.ok, result.observation


def test_look_for_observation_matches_the_paper_format(domain):
    result, _ = setup_ok(domain, [], "Look for eggs")
    assert result.observation.startswith("Found egg_carton_0 (carton of 12 eggs) in/on fridge_0, "
                                          "egg_0 (brown egg) in/on egg_carton_0")


def test_contents_are_listed_like_the_paper(domain):
    result, _ = setup_ok(domain, [], "Look for cereal")
    assert "cereal_box_4 (a box of cocoa puffs, contains cocoa_puffs_cereal) in/on cabinet_0" in result.observation
