"""A failed action is an observation, never an exception: thousands of random actions built from the
action forms with real, half-real and nonsense arguments."""

from __future__ import annotations

import random
import re

from adaptbench.runtime.env import Env

WORDS = ["egg_0", "pan_0", "stove_0", "whole_milk", "milk_0", "bowl_4", "table_0", "fridge_0", "kitchen", "salt",
         "scrambled", "xyz", "", "tomato_0", "toaster_0", "white_bread_slice", "bread_0", "kettle_0", "water",
         "sink_1", "mug_0", "coffee_grounds", "ice_cube", "egg_carton_0", "counter_0", '"hi"', "Egg_0", "é", "0"]


def _random_action(domain, rng: random.Random) -> str:
    form = rng.choice([f for a in domain.actions for f in a.forms] + ["Jump", "", "Move", "Pour x from"])
    return re.sub(r"\{(\w+)\}", lambda m: rng.choice(WORDS + list(domain.verbs)[:5]), form)


def test_random_actions_never_raise(domain):
    rng = random.Random(7)
    for episode in range(40):
        env = Env(domain, task=domain.tasks[episode % 8].id, persona=domain.personas[episode % 16].id,
                  seed=episode, user=lambda q, dialogue: "ok", max_steps=100)
        env.reset()
        for q in ("eggs", "pan", "milk", "bowl", "tomato", "bread", "mug", "coffee", "ice", "salt"):
            env.step(f"Look for {q}")
        for _ in range(60):
            r = env.step(_random_action(domain, rng))
            assert isinstance(r.observation, str)
        ev = env.evaluate()
        assert len(ev.verdicts) == len(env.persona.preferences)
