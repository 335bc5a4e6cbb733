"""Verifier semantics on small episodes: satisfied, violated and inapplicable, with reasons."""

from __future__ import annotations

import pytest

from adaptbench.compiler.model import Preference
from adaptbench.compiler.rules import parse_rule
from adaptbench.runtime.verify import Ctx, verdict

from .helpers import run

FIND = ["Look for eggs", "Look for bowl", "Look for pan", "Look for milk", "Look for cereal", "Look for plate",
        "Look for mug", "Look for coffee", "Look for cheese", "Look for salt", "Look for pepper", "Look for ice"]
EGGS = FIND + ["Move pan_1 to stove_0", "Move egg_0 to pan_1", "Pour whole_milk from milk_0 to pan_1",
               "Move cheddar_cheese from cheese_3 to pan_1", "Turn on stove_0",
               "scramble items in pan_1 to get scrambled_eggs", "Move plate_0 to table_1",
               "Move scrambled_eggs from pan_1 to plate_0"]
CEREAL_MILK_FIRST = FIND + ["Pour oat_milk from milk_1 to bowl_4", "Pour corn_flakes_cereal from cereal_box_5 to bowl_4",
                            "Move bowl_4 to table_0"]
CEREAL_FIRST = FIND + ["Pour corn_flakes_cereal from cereal_box_5 to bowl_4", "Pour oat_milk from milk_1 to bowl_4",
                       "Move bowl_4 to table_0"]
COFFEE = ["Pour water from sink_1 into kettle_0", "Turn on kettle_0", "Pour coffee_grounds from coffee_0 to mug_0",
          "Pour water from kettle_0 into mug_0", "Move mug_0 to table_0"]


def judge(domain, actions, rule, task="eggs"):
    env, results = run(domain, actions, task=task)
    for a, r in zip(actions, results, strict=True):
        assert r.ok, f"{a}: {r.observation}"
    pref = Preference("p", "text", parse_rule(rule), ("t",))
    return verdict(Ctx(domain, env.world, env.task), pref)


@pytest.mark.parametrize("rule,expected", [
    ("for egg_dish: it has whole_milk", "satisfied"),
    ("for egg_dish: it has oat_milk", "violated"),
    ("for egg_dish: it has no plant_based", "satisfied"),
    ("for egg_dish: it has heated cheese", "satisfied"),
    ("for egg_dish: it is scrambled", "satisfied"),
    ("for egg_dish: it is poached | omelette", "violated"),
    ("for egg_dish: it served at patio", "satisfied"),
    ("for egg_dish: it served at dining_room", "violated"),
    ("for egg_dish: it served in simple", "satisfied"),
    ("for egg_dish: it cooked in stainless | cast_iron", "satisfied"),
    ("for egg_dish: it cooked in non_stick", "violated"),
    ("for egg_dish: count(it, dairy) >= 2", "satisfied"),
    ("for egg_dish: count(it, dairy) >= 3", "violated"),
    ("for egg_dish: it has only (egg | dairy)", "satisfied"),
    ("for egg_dish: it has only (egg | milk)", "violated"),
    ("for egg_dish: it adds egg before milk", "satisfied"),
    ("for egg_dish: it adds milk before egg", "violated"),
    ("for egg_dish: uses pan & stainless", "satisfied"),
    ("for egg_dish: meal has avocado", "violated"),
    ("for cereal: it has milk", "inapplicable"),
    ("for egg_dish if available unicorn_0: it has milk", "inapplicable"),
    ("for egg_dish if available espresso_machine: it has milk", "satisfied"),
])
def test_rules_on_scrambled_eggs(domain, rule, expected):
    assert judge(domain, EGGS, rule).verdict == expected


def test_uncompleted_component_is_violated(domain):
    v = judge(domain, FIND, "for egg_dish: it has milk")
    assert v.verdict == "violated" and "eggs was not completed" in v.reason


def test_order_of_milk_and_cereal(domain):
    rule = "for cereal: it adds milk before breakfast_cereal"
    assert judge(domain, CEREAL_MILK_FIRST, rule, task="cereal").verdict == "satisfied"
    v = judge(domain, CEREAL_FIRST, rule, task="cereal")
    assert v.verdict == "violated" and "milk added before breakfast_cereal" in v.reason


def test_beverage_served_before_food(domain):
    rule = "for all if task has beverage and task has food: beverage served before food"
    cereal = CEREAL_MILK_FIRST[len(FIND):]
    assert judge(domain, FIND + COFFEE + cereal, rule, task="cereal_coffee").verdict == "satisfied"
    assert judge(domain, FIND + cereal + COFFEE, rule, task="cereal_coffee").verdict == "violated"
    assert judge(domain, CEREAL_MILK_FIRST, rule, task="cereal").verdict == "inapplicable"


def test_hot_and_iced_coffee(domain):
    cereal = CEREAL_FIRST[len(FIND):]
    hot = FIND + COFFEE + cereal
    assert judge(domain, hot, "for coffee: it is hot", task="cereal_coffee").verdict == "satisfied"
    assert judge(domain, hot, "for coffee: it is iced", task="cereal_coffee").verdict == "violated"
    iced = FIND + COFFEE + ["Move ice_cube from ice_tray_0 to mug_0"] + cereal
    assert judge(domain, iced, "for coffee: it is iced", task="cereal_coffee").verdict == "satisfied"
    assert judge(domain, iced, "for coffee: it is hot", task="cereal_coffee").verdict == "violated"


def test_reason_and_steps_point_at_the_deciding_step(domain):
    v = judge(domain, EGGS, "for egg_dish: it has no dairy")
    assert v.verdict == "violated" and "plate_0 has" in v.reason
    pour_step = EGGS.index("Pour whole_milk from milk_0 to pan_1") + 1
    assert pour_step in v.steps
