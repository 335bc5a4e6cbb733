"""The table as a person sees it: preparation versus topping, sides, serving time, per-dish conditions.

An examples registry in the spirit of unified-planning's `test/examples`: each case is a small trajectory,
a rule, the verdict the paper's sentence implies, and why.
"""

from __future__ import annotations

import pytest

from .test_verify import FIND, judge

FIND = FIND + ["Look for butter", "Look for avocado", "Look for tomato", "Look for ketchup", "Look for tray",
               "Look for honey", "Look for tea", "Look for kettle", "Look for cup"]
PAN = ["Move pan_1 to stove_0", "Move egg_0 to pan_1", "Move egg_1 to pan_1"]
SCRAMBLE = ["Turn on stove_0", "scramble items in pan_1 to get scrambled_eggs",
            "Move scrambled_eggs from pan_1 to plate_0"]
MILK_IN = FIND + PAN + ["Pour whole_milk from milk_0 to pan_1"] + SCRAMBLE + ["Move plate_0 to table_1"]
MILK_OVER = FIND + PAN + SCRAMBLE + ["Pour whole_milk from milk_0 to plate_0", "Move plate_0 to table_1"]
CHEESE_ON = FIND + PAN + SCRAMBLE + ["Move cheddar_cheese from cheese_3 to plate_0", "Move plate_0 to table_1"]
EGGS = FIND + PAN + SCRAMBLE + ["Move plate_0 to table_1"]
AVOCADO_SIDE = EGGS + ["Move avocado_0 to plate_1", "Move plate_1 to table_1"]
AVOCADO_ELSEWHERE = EGGS + ["Move avocado_0 to plate_1", "Move plate_1 to desk_0"]
TEA = ["Pour water from sink_1 into kettle_0", "Turn on kettle_0", "Move chamomile_tea_bag from tea_bags_2 to cup_0",
       "Pour water from kettle_0 into cup_0"]
TOMATO_IN_TEA = FIND + TEA + ["Move tomato_0 to cup_0", "Move cup_0 to table_1"] + PAN + SCRAMBLE + [
    "Move plate_0 to table_1"]
KETCHUP_BESIDE = EGGS + ["Move ketchup_0 to table_1"]
TEA_THEN_EGGS = FIND + TEA + ["Move cup_0 to table_1"] + PAN + SCRAMBLE + ["Move plate_0 to table_1"]
TEA_REDATED = TEA_THEN_EGGS + ["Pour honey from honey_0 to cup_0"]
TRAY = FIND + TEA + PAN + SCRAMBLE + ["Move tray_0 to counter_0", "Move cup_0 to tray_0", "Move plate_0 to tray_0",
                                      "Move tray_0 to table_1"]
CEREAL_DRY = FIND + ["Pour corn_flakes_cereal from cereal_box_5 to bowl_4", "Move bowl_4 to table_0"]
CEREAL_OAT = FIND + ["Pour oat_milk from milk_1 to bowl_4", "Pour corn_flakes_cereal from cereal_box_5 to bowl_4",
                     "Move bowl_4 to table_0"]

CASES = [
    # preparation versus topping
    ("milk while preparing", MILK_IN, "for egg_dish: it made with whole_milk", "satisfied", "eggs"),
    ("cold milk poured over is not milk while preparing", MILK_OVER, "for egg_dish: it made with milk",
     "violated", "eggs"),
    ("cold milk poured over is a topping", MILK_OVER, "for egg_dish: it topped with milk", "satisfied", "eggs"),
    ("milk in the pan is no topping", MILK_IN, "for egg_dish: it topped with milk", "violated", "eggs"),
    ("has is either", MILK_OVER, "for egg_dish: it has milk", "satisfied", "eggs"),
    ("cheese on cooked eggs is topped", CHEESE_ON, "for egg_dish: it topped with cheese", "satisfied", "eggs"),
    ("cheese on cooked eggs was not cooked with them", CHEESE_ON, "for egg_dish: it made with cheese", "violated",
     "eggs"),
    # sides
    ("an avocado on its own plate at the same table is a side", AVOCADO_SIDE, "for egg_dish: sides has avocado",
     "satisfied", "eggs"),
    ("an avocado at another place is no side", AVOCADO_ELSEWHERE, "for egg_dish: sides has avocado", "violated",
     "eggs"),
    ("a ketchup bottle beside the eggs is a side", KETCHUP_BESIDE, "for egg_dish: sides has condiment",
     "satisfied", "eggs"),
    ("the eggs are not their own side", EGGS, "for egg_dish: sides has egg", "violated", "eggs"),
    ("a tomato in the tea is not a vegetable with the eggs", TOMATO_IN_TEA,
     "for egg_dish: it has vegetable or sides has vegetable", "violated", "tea_eggs"),
    # serving time
    ("tea first, then eggs", TEA_THEN_EGGS, "for all: beverage served before food", "satisfied", "tea_eggs"),
    ("honey on a served tea does not re-date it", TEA_REDATED, "for all: beverage served before food",
     "satisfied", "tea_eggs"),
    ("carried together on a tray: neither is first", TRAY, "for all: beverage served before food", "violated",
     "tea_eggs"),
    ("carried together on a tray: neither is first (the other way)", TRAY, "for all: food served before beverage",
     "violated", "tea_eggs"),
    # conditions on the dish
    ("no milk: a rule about the milk does not apply", CEREAL_DRY,
     "for cereal if it has milk: it has no (milk & !lactose_free)", "inapplicable", "cereal"),
    ("oat milk: the rule applies", CEREAL_OAT, "for cereal if it has milk: it has milk & plant_based", "satisfied",
     "cereal"),
    ("ordering without its subject is inapplicable", CEREAL_DRY,
     "for cereal if it has milk: it adds milk before breakfast_cereal", "inapplicable", "cereal"),
    ("ordering with its subject", CEREAL_OAT, "for cereal if it has milk: it adds milk before breakfast_cereal",
     "satisfied", "cereal"),
    ("an uncompleted target is still violated", FIND, "for cereal if it has milk: it has milk", "violated",
     "cereal"),
]


@pytest.mark.parametrize("name,actions,rule,expected,task", CASES, ids=[c[0] for c in CASES])
def test_table_semantics(domain, name, actions, rule, expected, task):
    v = judge(domain, actions, rule, task=task)
    assert v.verdict == expected, f"{name}: {v.verdict} ({v.reason})"


# ---- styles by process, never by name
def _eggs(*steps, pan="pan_1", extra=()):
    return FIND + ["Look for oil", "Move pan_1 to stove_0", "Move egg_0 to pan_1", "Move egg_1 to pan_1", *extra,
                   *steps, "Move plate_0 to table_1"]


FRIED_NAMED_POACHED = _eggs("Turn on stove_0", "fry items in pan_1 to get poached_eggs",
                            "Move poached_eggs from pan_1 to plate_0")
MIXED_NAMED_OMELETTE = FIND + ["Move egg_0 to bowl_4", "Mix all items in bowl_4 to get omelette", "Move bowl_4 to table_1"]
BEATEN_COOKED = _eggs("whisk items in pan_1 to get beaten", "Turn on stove_0", "Cook items in pan_1 to get eggs",
                      "Move eggs from pan_1 to plate_0")
BEATEN_SCRAMBLED = _eggs("whisk items in pan_1 to get beaten", "Turn on stove_0",
                         "scramble items in pan_1 to get omelette", "Move omelette from pan_1 to plate_0")
POACHED = _eggs("crack items in pan_1 to get cracked_eggs", "Pour water from sink_1 into pan_1",
                "Pour salt from salt_box_0 to pan_1", "Turn on stove_0", "Cook items in pan_1 to get eggs",
                "Move eggs from pan_1 to plate_0")
# whole eggs in a pot of water on heat: boiled in the shell, whatever the agent calls the step
SHELL_POACHED = _eggs("Pour water from sink_1 into pan_1", "Turn on stove_0", "poach items in pan_1 to get poached_eggs",
                      "Move poached_eggs from pan_1 to plate_0")
BOILED = FIND + ["Look for pot", "Move pot_0 to stove_0", "Pour water from sink_1 into pot_0", "Move egg_0 to pot_0",
                 "Move egg_1 to pot_0", "Turn on stove_0", "Move egg_0 from pot_0 to plate_0",
                 "Move egg_1 from pot_0 to plate_0", "Move plate_0 to table_1"]
BOILED_PEELED = FIND + ["Look for pot", "Move pot_0 to stove_0", "Pour water from sink_1 into pot_0",
                        "Move egg_0 to pot_0", "Turn on stove_0", "Move egg_0 from pot_0 to plate_0",
                        "peel egg_0 to get peeled_egg", "Move plate_0 to table_1"]
DRY_WHOLE = FIND + ["Look for pot", "Move pot_0 to stove_0", "Move egg_0 to pot_0", "Turn on stove_0",
                    "Move egg_0 from pot_0 to plate_0", "Move plate_0 to table_1"]
FLIPPED = _eggs("Turn on stove_0", "fry items in pan_1 to get eggs", "flip items in pan_1 to get eggs",
                "Move eggs from pan_1 to plate_0")
UNFLIPPED = _eggs("Turn on stove_0", "fry items in pan_1 to get over_easy_eggs",
                  "Move over_easy_eggs from pan_1 to plate_0")
HOT_COFFEE = FIND + ["Look for kettle", "Pour water from sink_1 into kettle_0", "Turn on kettle_0",
                     "Pour coffee_grounds from coffee_0 to mug_0", "Pour water from kettle_0 into mug_0"]
CHILLED_COFFEE = HOT_COFFEE + ["chill items in mug_0 to get hot_coffee", "Move mug_0 to table_0"]
FRIDGE_COFFEE = HOT_COFFEE + ["Open fridge_0", "Move mug_0 to fridge_0", "Move mug_0 to table_0"]
COOLED_COFFEE = HOT_COFFEE + ["cool items in mug_0 to get coffee", "Move mug_0 to table_0"]
ICE_COFFEE = HOT_COFFEE + ["Move ice_cube from ice_tray_0 to mug_0", "Move mug_0 to table_0"]
REHEATED_COFFEE = HOT_COFFEE + ["Open fridge_0", "Move mug_0 to fridge_0", "Look for microwave",
                                "Move mug_0 to microwave_0", "Turn on microwave_0", "Move mug_0 to table_0"]
FRIDGE_POUR_COFFEE = FIND + ["Look for kettle", "Pour water from sink_1 into kettle_0", "Turn on kettle_0",
                             "Pour coffee_grounds from coffee_0 to mug_0", "Open fridge_0", "Move mug_0 to fridge_0",
                             "Pour water from kettle_0 into mug_0", "Move mug_0 to table_0"]
COLD_MILK = FIND + ["Pour whole_milk from milk_0 to mug_0", "Move mug_0 to table_0"]

STYLE_CASES = [
    ("fried eggs named poached are not poached", FRIED_NAMED_POACHED, "for egg_dish: it is poached", "violated"),
    ("fried eggs named poached are fried", FRIED_NAMED_POACHED, "for egg_dish: it is fried", "satisfied"),
    ("mixing in a bowl makes no omelette", MIXED_NAMED_OMELETTE, "for eggs: it is omelette", "violated"),
    ("beaten then cooked unstirred is an omelette", BEATEN_COOKED, "for egg_dish: it is omelette", "satisfied"),
    ("beaten then cooked unstirred is not scrambled", BEATEN_COOKED, "for egg_dish: it is scrambled", "violated"),
    ("beaten then scrambled is scrambled, whatever its name", BEATEN_SCRAMBLED, "for egg_dish: it is scrambled",
     "satisfied"),
    ("beaten then scrambled is no omelette", BEATEN_SCRAMBLED, "for egg_dish: it is omelette", "violated"),
    ("cracked then cooked in water is poached", POACHED, "for egg_dish: it is poached", "satisfied"),
    ("cracked then cooked in water is not boiled", POACHED, "for egg_dish: it is boiled", "violated"),
    ("whole eggs in hot water are boiled, whatever the step is called", SHELL_POACHED, "for egg_dish: it is boiled",
     "satisfied"),
    ("whole eggs in hot water are not poached", SHELL_POACHED, "for egg_dish: it is poached", "violated"),
    ("eggs boiled in the shell in a pot are boiled", BOILED, "for egg_dish: it is boiled", "satisfied"),
    ("eggs boiled in the shell are neither poached nor fried", BOILED, "for egg_dish: it is poached | fried",
     "violated"),
    ("a boiled egg peeled afterwards is still boiled", BOILED_PEELED, "for egg_dish: it is boiled", "satisfied"),
    ("the water a shell egg boiled in stays in the pot", BOILED, "for egg_dish: it has no water", "satisfied"),
    ("whole eggs heated in a dry pot are not boiled", DRY_WHOLE, "for egg_dish: it is boiled", "violated"),
    ("poaching water is no ingredient", POACHED, "for egg_dish: it has only (egg | salt)", "satisfied"),
    ("poaching water is no ingredient (has no)", POACHED, "for egg_dish: it has no water", "satisfied"),
    ("fried and flipped is over easy", FLIPPED, "for egg_dish: it is over_easy", "satisfied"),
    ("fried and flipped is not sunny-side up", FLIPPED, "for egg_dish: it is sunny_side_up", "violated"),
    ("fried unflipped is not over easy, whatever its name", UNFLIPPED, "for egg_dish: it is over_easy", "violated"),
    ("fried unflipped is sunny-side up", UNFLIPPED, "for egg_dish: it is sunny_side_up", "satisfied"),
    ("beating is a verb group", BEATEN_COOKED, "for egg_dish: it made by beating", "satisfied"),
]


@pytest.mark.parametrize("name,actions,rule,expected", STYLE_CASES, ids=[c[0] for c in STYLE_CASES])
def test_styles_by_process(domain, name, actions, rule, expected):
    v = judge(domain, actions, rule, task="eggs")
    assert v.verdict == expected, f"{name}: {v.verdict} ({v.reason})"


@pytest.mark.parametrize("actions,expected", [(HOT_COFFEE + ["Move mug_0 to table_0"], "satisfied"),
                                              (CHILLED_COFFEE, "violated")])
def test_hot_means_served_while_heated(domain, actions, expected):
    assert judge(domain, actions, "for coffee: it is hot", task="toast_coffee").verdict == expected


TEMPERATURE_CASES = [
    ("chilled in the fridge after brewing is not hot", FRIDGE_COFFEE, "hot", "violated"),
    ("chilled in the fridge after brewing is iced", FRIDGE_COFFEE, "iced", "satisfied"),
    ("a chilling verb makes it iced", CHILLED_COFFEE, "iced", "satisfied"),
    ("cooled on the counter is not hot", COOLED_COFFEE, "hot", "violated"),
    ("cooled on the counter is not iced either", COOLED_COFFEE, "iced", "violated"),
    ("ice in a hot coffee: iced, not hot", ICE_COFFEE, "iced", "satisfied"),
    ("ice in a hot coffee is not hot", ICE_COFFEE, "hot", "violated"),
    ("hot from the kettle is not iced", HOT_COFFEE + ["Move mug_0 to table_0"], "iced", "violated"),
    ("chilled, then reheated in the microwave, is hot again", REHEATED_COFFEE, "hot", "satisfied"),
    ("hot water poured into a cup standing in the fridge goes into the fridge: not hot", FRIDGE_POUR_COFFEE, "hot",
     "violated"),
    ("cold milk from the fridge is neither hot", COLD_MILK, "hot", "violated"),
    ("nor iced: it was never chilled here nor iced", COLD_MILK, "iced", "violated"),
]


@pytest.mark.parametrize("name,actions,style,expected", TEMPERATURE_CASES, ids=[c[0] for c in TEMPERATURE_CASES])
def test_hot_and_iced_follow_the_kitchen(domain, name, actions, style, expected):
    v = judge(domain, actions, f"for coffee: it is {style}", task="toast_coffee")
    assert v.verdict == expected, f"{name}: {v.verdict} ({v.reason})"


# ---- uses: took part
SPATULA_IN_PAN = FIND + ["Look for spatula", "Move pan_1 to stove_0", "Move spatula_1 to pan_1", "Move egg_0 to pan_1",
                         "Turn on stove_0", "scramble items in pan_1 to get eggs", "Move eggs from pan_1 to plate_0",
                         "Move plate_0 to table_1"]
SPATULA_MOVED = FIND + ["Look for spatula", "Move spatula_1 to counter_0", "Move pan_1 to stove_0",
                        "Move egg_0 to pan_1", "Turn on stove_0", "scramble items in pan_1 to get eggs",
                        "Move eggs from pan_1 to plate_0", "Move plate_0 to table_1"]
SPATULA_AFTER = FIND + ["Look for spatula", "Move pan_1 to stove_0", "Move egg_0 to pan_1", "Turn on stove_0",
                        "scramble items in pan_1 to get eggs", "Move eggs from pan_1 to plate_0",
                        "Move spatula_1 to pan_1", "Move plate_0 to table_1"]


@pytest.mark.parametrize("actions,rule,expected", [
    (SPATULA_IN_PAN, "for egg_dish: uses spatula", "satisfied"),
    (SPATULA_IN_PAN, "for egg_dish: it uses spatula", "satisfied"),
    (SPATULA_MOVED, "for egg_dish: uses spatula", "violated"),
    (SPATULA_AFTER, "for egg_dish: uses spatula", "violated"),
    (SPATULA_MOVED, "for egg_dish: uses stove", "satisfied"),
])
def test_uses_means_took_part(domain, actions, rule, expected):
    assert judge(domain, actions, rule).verdict == expected


# ---- sweet or savory per dish
TOAST = FIND + ["Look for bread", "Look for toaster", "Look for jam", "Move white_bread_slice from bread_0 to toaster_0",
                "Turn on toaster_0", "Move white_bread_slice from toaster_0 to plate_1"]
JAM_TOAST = TOAST + ["Move mixed_fruit_jam from jam_0 to plate_1", "Move plate_1 to table_1"]
AVOCADO_TOAST = TOAST + ["Move avocado_0 to plate_1", "Move plate_1 to table_1"]


@pytest.mark.parametrize("actions,rule,expected", [
    (JAM_TOAST, "for sweet: it has sweet_spread", "satisfied"),
    (JAM_TOAST, "for savory: sides has vegetable", "inapplicable"),
    (AVOCADO_TOAST, "for savory: it has avocado", "satisfied"),
    (AVOCADO_TOAST, "for sweet: it has sweet_spread", "inapplicable"),
    (JAM_TOAST, "for toast: it has sweet_spread", "satisfied"),
    (FIND, "for savory: it has avocado", "violated"),  # toast not made: its own kind (savory) applies
    (FIND, "for sweet: it has sweet_spread", "inapplicable"),
])
def test_sweet_or_savory_per_dish(domain, actions, rule, expected):
    assert judge(domain, actions, rule, task="toast_coffee").verdict == expected


# ---- more of the paper's sentences (issue 6, items 2 and 3)
FRIED_IN_OIL = FIND + ["Look for oil", "Move pan_1 to stove_0", "Pour vegetable_oil from oil_bottle_1 to pan_1",
                       "Move egg_0 to pan_1", "Turn on stove_0", "fry items in pan_1 to get eggs",
                       "Move eggs from pan_1 to plate_0"]
BUTTER_PAT = FRIED_IN_OIL + ["Move butter from butter_0 to plate_0", "Move plate_0 to table_1"]
BUTTER_IN_PAN = FIND + ["Look for oil", "Move pan_1 to stove_0", "Move butter from butter_0 to pan_1",
                        "Move egg_0 to pan_1", "Turn on stove_0", "fry items in pan_1 to get eggs",
                        "Move eggs from pan_1 to plate_0", "Move plate_0 to table_1"]
HOT_SAUCE_IN_TEA = FIND + ["Look for hot sauce"] + TEA + ["Pour tabasco_hot_sauce from hot_sauce_1 to cup_0",
                                                           "Move cup_0 to table_1"] + PAN + SCRAMBLE + [
    "Move plate_0 to table_1"]


@pytest.mark.parametrize("actions,rule,expected,task", [
    (BUTTER_PAT, "for egg_dish: it made with butter", "violated", "eggs"),
    (BUTTER_PAT, "for egg_dish: it made with oil", "satisfied", "eggs"),
    (BUTTER_PAT, "for egg_dish: it topped with butter", "satisfied", "eggs"),
    (BUTTER_IN_PAN, "for egg_dish: it made with butter", "satisfied", "eggs"),
    (HOT_SAUCE_IN_TEA, "for egg_dish: it has condiment or sides has condiment", "violated", "tea_eggs"),
    (HOT_SAUCE_IN_TEA, "meal has condiment", "satisfied", "tea_eggs"),
])
def test_paper_sentences(domain, actions, rule, expected, task):
    v = judge(domain, actions, rule, task=task)
    assert v.verdict == expected, v.reason


def test_tea_bag_under_the_hot_water_is_made_with(domain):
    actions = FIND + TEA + ["Move cup_0 to table_1"]
    assert judge(domain, actions, "for tea: it made with tea_bag", task="tea_eggs").verdict == "satisfied"
    honey = actions + ["Pour honey from honey_0 to cup_0"]
    assert judge(domain, honey, "for tea: it topped with honey", task="tea_eggs").verdict == "satisfied"
    assert judge(domain, honey, "for tea: it made with honey", task="tea_eggs").verdict == "violated"


# ---- every object of the sentence is checked: `each S with X (...)` (issue 6, item 12)
SEASONED_EGGS = FIND + ["Look for pepper"] + PAN + ["Move salt from salt_box_0 to pan_1",
                                                    "Move pepper from pepper_0 to pan_1"] + SCRAMBLE
TOMATO_SIDE = ["Move tomato_0 to plate_1", "Move plate_1 to table_1"]
SALTED_TOMATO_SIDE = ["Move tomato_0 to plate_1", "Move salt from salt_box_0 to plate_1",
                      "Move pepper from pepper_0 to plate_1", "Move plate_1 to table_1"]
SALT_AND_PEPPER = "for egg_dish: it has salt and it has pepper and each sides with vegetable (it has salt and it has pepper)"
EACH_CASES = [
    ("eggs and vegetable side both seasoned", SEASONED_EGGS + ["Move plate_0 to table_1"] + SALTED_TOMATO_SIDE,
     "satisfied"),
    ("an unseasoned vegetable side breaks 'salt and pepper on eggs and vegetables'",
     SEASONED_EGGS + ["Move plate_0 to table_1"] + TOMATO_SIDE, "violated"),
    ("no vegetable served: only the eggs are checked", SEASONED_EGGS + ["Move plate_0 to table_1"], "satisfied"),
    ("a tomato placed unseasoned on the seasoned eggs is an unseasoned vegetable",
     SEASONED_EGGS + ["Move tomato_0 to plate_0", "Move plate_0 to table_1"], "violated"),
    ("seasoned vegetables but plain eggs", FIND + ["Look for pepper"] + PAN + SCRAMBLE + ["Move plate_0 to table_1"]
     + SALTED_TOMATO_SIDE, "violated"),
]


@pytest.mark.parametrize("name,actions,expected", EACH_CASES, ids=[c[0] for c in EACH_CASES])
def test_each_object_of_the_sentence(domain, name, actions, expected):
    v = judge(domain, actions, SALT_AND_PEPPER, task="eggs")
    assert v.verdict == expected, f"{name}: {v.verdict} ({v.reason})"


def test_each_parses_and_is_checked(domain):
    from adaptbench.compiler import ast as A
    from adaptbench.compiler.rules import parse_rule

    rule = parse_rule("for egg_dish: each sides with (vegetable | meat) (count(it, spice) >= 2)")
    each = rule.expr
    assert isinstance(each, A.Each) and each.subject == "sides" and each.cls is not None
    assert A.from_data(A.to_data(rule)) == rule
    plain = parse_rule("for toast: each it (it has butter)").expr
    assert isinstance(plain, A.Each) and plain.cls is None


# ---- free: availability that counts use (issue 30)
FANCY_EGGS = FIND + PAN + ["Turn on stove_0", "scramble items in pan_1 to get scrambled_eggs",
                           "Move scrambled_eggs from pan_1 to plate_8", "Move plate_8 to table_1"]
SIDE_PLAIN = ["Move avocado_0 to plate_2", "Move plate_2 to table_1"]
DESSERT_ON_9 = ["Look for strawberries", "Move strawberry from strawberries_box_0 to plate_9"]
FREE_PLATE = "for egg_dish: each meal (it served in fancy or not (it served in plate and free (fancy & plate) for it))"


@pytest.mark.parametrize("name,actions,rule,expected", [
    ("a plain side plate while the second fancy plate stood empty", FANCY_EGGS + SIDE_PLAIN, FREE_PLATE, "violated"),
    ("the second fancy plate serves the dessert: the plain side plate is all there was",
     FANCY_EGGS + DESSERT_ON_9 + ["Move plate_9 to table_1"] + SIDE_PLAIN, FREE_PLATE, "satisfied"),
    ("the dessert plate served later is in use even though it was empty when the side was plated",
     FANCY_EGGS + SIDE_PLAIN + DESSERT_ON_9 + ["Move plate_9 to table_1"], FREE_PLATE, "satisfied"),
    ("a fancy plate holding food that never reaches the table was idle: free",
     FANCY_EGGS + DESSERT_ON_9 + SIDE_PLAIN, FREE_PLATE, "violated"),
    ("the dish's own vessel is not 'another' free one", FANCY_EGGS, "for egg_dish: free (fancy & plate) for it",
     "satisfied"),
    ("no fancy bowl taken: both are free for the eggs", FANCY_EGGS, "for egg_dish: free (fancy & bowl) for it",
     "satisfied"),
])
def test_free_counts_use(domain, name, actions, rule, expected):
    v = judge(domain, actions, rule, task="eggs")
    assert v.verdict == expected, f"{name}: {v.verdict} ({v.reason})"


def test_free_is_false_when_every_matching_vessel_is_taken(domain):
    actions = FANCY_EGGS + DESSERT_ON_9 + ["Move plate_9 to table_1"]
    v = judge(domain, actions, "for egg_dish: free (fancy & plate) for it", task="eggs")
    assert v.verdict == "violated" and "no fancy & plate free" in v.reason


def test_the_fill_log_dates_when_a_vessel_began_to_hold_food(domain):
    from .helpers import run

    env, _ = run(domain, FANCY_EGGS + DESSERT_ON_9, task="eggs")
    w, step = env.world, FANCY_EGGS.index("Move scrambled_eggs from pan_1 to plate_8") + 1
    assert w.filled_at("plate_8") == step and w.held_food("plate_8", step) and not w.held_food("plate_8", step - 1)
    assert w.held_food("pan_1", step - 1) and not w.held_food("pan_1", step)  # emptied onto the plate
    assert not w.held_food("plate_2", step) and w.filled_at("plate_2") == 0  # never used


def test_a_spatula_in_the_pan_a_whole_item_was_heated_in_took_part(domain):
    actions = FIND + ["Look for spatula", "Move pan_1 to stove_0", "Move spatula_2 to pan_1", "Move tomato_0 to pan_1",
                      "Turn on stove_0", "Move tomato_0 to plate_2", "Move plate_2 to table_1"]
    from .helpers import run

    env, results = run(domain, actions, task="eggs")
    assert all(r.ok for r in results) and "spatula_2" in env.world.used


@pytest.mark.parametrize("rule,expected", [
    # in `for all`, `sides` is the whole table: no milk anywhere, nothing to say, finished or not
    ("for all if meal has milk or sides has milk: meal has no (milk & !dairy) and sides has no (milk & !dairy)",
     "inapplicable"),
    # about a dish's own sides: the paper's rule first, an unfinished dish is violated
    ("for egg_dish if sides has milk: sides has no (milk & !dairy)", "violated"),
    # `it` inside an `each` of the condition: per dish, so the unfinished eggs are violated
    ("for all if not each meal (not it served in fancy): each meal (it served in fancy)", "violated"),
])
def test_which_conditions_wait_for_completion(domain, rule, expected):
    assert judge(domain, FIND, rule, task="eggs").verdict == expected
