"""Every action: a success case and a case for each failed precondition.

A failure is an observation naming what failed (never an exception)."""

from __future__ import annotations

import pytest

from .helpers import run, setup_ok

FIND = ["Look for eggs", "Look for bowl", "Look for pan", "Look for milk", "Look for tomato", "Look for spoon"]
PAN_ON_STOVE = FIND + ["Move pan_0 to stove_0"]

CASES = [
    # (id, setup, action, ok, expected text in observation)
    ("search", [], "Search cabinet_3", True, "pan_0 (classic non-stick pan) in/on cabinet_3"),
    ("search-unknown", [], "Search cabinett_3", False, "did you mean cabinet_3"),
    ("search-unfound", [], "Search egg_carton_0", False, "that you have found"),
    ("look_for", [], "Look for eggs", True, "egg_carton_0 (carton of 12 eggs) in/on fridge_0"),
    ("look_for-nothing", [], "Look for unicorn", True, "Could not find any unicorn"),
    ("open", [], "Open fridge_0", True, "Opened fridge_0"),
    ("open-not-openable", [], "Open table_0", False, "table_0 cannot be opened"),
    ("close", [], "Close cabinet_0", True, "Closed cabinet_0"),
    ("close-not-openable", [], "Close counter_0", False, "counter_0 cannot be closed"),
    ("turn_on", [], "Turn on stove_0", True, "Turned on stove_0"),
    ("turn_on-not-appliance", [], "Turn on table_0", False, "table_0 is not a cooking appliance"),
    ("turn_off", [], "Turn off kettle_0", True, "Turned off kettle_0"),
    ("turn_off-not-appliance", [], "Turn off sofa_0", False, "sofa_0 is not a cooking appliance"),
    ("heat", PAN_ON_STOVE + ["Move egg_0 to pan_0"], "Heat pan_0", True, "Heated pan_0"),
    ("heat-content", PAN_ON_STOVE + ["Pour whole_milk from milk_0 to pan_0"], "Heat whole_milk", True, "Heated whole_milk"),
    ("heat-off-appliance", FIND, "Heat egg_0", False, "nor the container holding it is on or in a cooking appliance"),
    ("move_from", FIND, "Move egg_0 from egg_carton_0 to bowl_0", True, "Moved egg_0 from egg_carton_0 to bowl_0"),
    ("move_from-content", FIND, "Move whole_milk from milk_0 to bowl_0", True, "Moved whole_milk"),
    ("move_from-not-there", FIND, "Move egg_0 from fridge_0 to bowl_0", False, "fridge_0 does not contain egg_0"),
    ("move_from-into-itself", FIND, "Move bowl_0 from cabinet_1 to bowl_0", False, "cannot move bowl_0 into itself"),
    ("move", FIND, "Move bowl_0 to table_0", True, "Moved bowl_0 to table_0"),
    ("move-serve-form", FIND, "Serve the object bowl_0 at table_1", True, "Moved bowl_0 to table_1"),
    ("move-place-form", FIND, "Place the object bowl_0 at island_0", True, "Moved bowl_0 to island_0"),
    ("move-place-on-form", FIND, "Place bowl_0 on desk_0", True, "Moved bowl_0 to desk_0"),
    ("move-fixed", [], "Move fridge_0 to kitchen", False, "fridge_0 is fixed in place"),
    ("move-into-itself", FIND, "Move bowl_0 to bowl_0", False, "cannot move bowl_0 into itself"),
    ("move-content-not-container", FIND, "Move whole_milk from milk_0 to spoon_0", False, "spoon_0 is not a container"),
    ("pour", FIND, "Pour whole_milk from milk_0 to bowl_0", True, "Poured whole_milk from milk_0 into bowl_0"),
    ("pour-into-form", FIND, "Pour whole_milk from milk_0 into bowl_0", True, "Poured whole_milk"),
    ("pour-wrong-source", FIND, "Pour whole_milk from milk_1 to bowl_0", False, "milk_1 does not contain whole_milk"),
    ("pour-not-container", FIND, "Pour whole_milk from milk_0 to spoon_0", False, "spoon_0 is not a container"),
    ("mix", FIND + ["Move egg_0 to bowl_0", "Pour whole_milk from milk_0 to bowl_0"],
     "Mix all items in bowl_0 to get egg_mix", True, "Mixed all items in bowl_0 to get egg_mix"),
    ("mix-not-container", FIND, "Mix all items in spoon_0 to get mush", False, "spoon_0 is not a container"),
    ("mix-empty", FIND, "Mix all items in bowl_1 to get mush", False, "bowl_1 holds nothing edible to mix"),
    ("cook", PAN_ON_STOVE + ["Move egg_0 to pan_0"], "Cook items in pan_0 to get fried_egg", True, "Cooked items in pan_0"),
    ("cook-off-appliance", FIND + ["Move egg_0 to bowl_0"], "Cook items in bowl_0 to get x", False,
     "bowl_0 is not on or in a cooking appliance"),
    ("cook-empty", PAN_ON_STOVE, "Cook items in pan_0 to get x", False, "pan_0 holds nothing edible to cook"),
    ("chop", FIND + ["Move tomato_0 to counter_0"], "Chop tomato_0 to get chopped_tomato", True,
     "Chopped tomato_0 to get chopped_tomato"),
    ("chop-on-board", FIND + ["Search cabinet_3", "Move cutting_board_1 to counter_1", "Move tomato_0 to cutting_board_1"],
     "Chop tomato_0 to get chopped_tomato", True, "Chopped tomato_0"),
    ("chop-not-on-surface", FIND, "Chop tomato_0 to get chopped_tomato", False, "tomato_0 is not on a chopping surface"),
    ("chop-not-edible", FIND + ["Move bowl_0 to counter_0"], "Chop bowl_0 to get shards", False, "bowl_0 is not edible"),
    ("chop-name-taken", FIND + ["Move tomato_0 to counter_0"], "Chop tomato_0 to get bowl_1", False,
     "the name 'bowl_1' is already taken"),
    ("freeform_items", FIND + ["Move egg_0 to bowl_0"], "whisk items in bowl_0 to get egg_mix", True,
     "Applied whisk to items in bowl_0 to get egg_mix"),
    ("freeform_items-empty", FIND, "whisk items in bowl_0 to get egg_mix", False, "bowl_0 holds nothing edible"),
    ("freeform_items-heating-off-appliance", FIND + ["Move egg_0 to bowl_0"], "fry items in bowl_0 to get x", False,
     "to fry items, bowl_0 must be on or in a cooking appliance"),
    ("freeform_items-unknown-verb", FIND + ["Move egg_0 to bowl_0"], "zorp items in bowl_0 to get x", False,
     "'zorp' is not a verb I know"),
    ("freeform_object", FIND, "crack the object egg_0 to get cracked_egg", True, "Applied crack to egg_0 to get cracked_egg"),
    ("freeform_object-short-form", FIND, "brew coffee_grounds to get brewed_coffee", False, "have found"),
    ("freeform_object-not-edible", FIND, "crack the object bowl_0 to get shards", False, "bowl_0 is not edible"),
    ("freeform_object-cutting-off-surface", FIND, "slice the object tomato_0 to get slices", False,
     "it must be on a chopping surface"),
    ("freeform_object-heating-off-appliance", FIND, "fry the object egg_0 to get fried_egg", False,
     "it must be on or in a cooking appliance"),
    ("ask", [], 'Ask "How do you like your eggs?"', True, ""),
    ("done", [], "Declare Done", True, "Done"),
    ("unknown-action", [], "Dance wildly", False, "I don't understand 'Dance wildly'"),
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_action(domain, case):
    _, setup, action, ok, text = case
    result, _ = setup_ok(domain, setup, action)
    assert result.ok is ok, result.observation
    assert text in result.observation


def test_every_action_has_a_success_and_a_failure_case(domain):
    ids = {c[0].split("-")[0] for c in CASES}
    failing = {c[0].split("-")[0] for c in CASES if not c[3]}
    assert {a.id for a in domain.actions} <= ids
    with_pre = {a.id for a in domain.actions if a.preconditions}
    assert with_pre <= failing


def test_repeat_rule_fails_the_third_repeat_within_four_steps(domain):
    _, rs = run(domain, ["Open fridge_0", "Open fridge_0", "Open fridge_0", "Close fridge_0"])
    assert [r.ok for r in rs] == [True, True, False, True]
    assert "too many times" in rs[2].observation


def test_step_limit_ends_the_episode(domain):
    env, rs = run(domain, ["Open fridge_0", "Close fridge_0"] * 3, max_steps=5)
    assert rs[4].done and env.done
    assert rs[5].observation == "The episode is over."


def test_failed_action_never_raises_on_garbage(domain):
    env, rs = run(domain, ["", "   ", "Move", 'Ask "unterminated', "Pour from to", "Look for", "Declare"])
    assert all(isinstance(r.observation, str) for r in rs)


def test_result_of_a_transformation_keeps_provenance(domain):
    env, rs = run(domain, FIND + ["Move tomato_0 to counter_0", "Chop tomato_0 to get chopped_tomato"])
    node = env.world.nodes["chopped_tomato"]
    assert node.cut and node.verb == "chop" and node.inputs[0].entity == "tomato_0"
    assert "tomato_0" not in env.world.specs
