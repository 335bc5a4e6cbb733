"""Scripted agents: they explore before using things, follow answers, and the oracle beats never-ask."""

from __future__ import annotations

from adaptbench.agents.plans import all_recipes, choice_points, defaults, execute
from adaptbench.agents.scripted import Oracle, departures, interpret, play
from adaptbench.agents.users import OfflineUser
from adaptbench.compiler.model import Persona, Preference
from adaptbench.compiler.rules import parse_rule
from adaptbench.runtime.env import Env


def _zed(domain):
    prefs = (
        Preference("oat", "Oat milk in coffee", parse_rule("for coffee: it has oat_milk"), ("coffee", "milk"),
                   "I take my coffee with oat milk."),
        Preference("patio", "Patio", parse_rule("for all: it served at patio"), ("where", "eat", "breakfast"),
                   "On the patio, please."),
        Preference("bev_first", "Drink first",
                   parse_rule("for all if task has beverage and task has food: beverage served before food"),
                   ("drink", "before", "after", "food"), "Serve my drink before the food."),
    )
    return Persona("zed", "Zed", 99, "", prefs)


def _run(domain, agent, task="toast_coffee", seed=0):
    persona = _zed(domain)
    env = Env(domain, task=task, persona=persona, seed=seed, user=OfflineUser(domain, persona, domain.task[task]))
    env.reset()
    play(agent, env)
    return env, env.evaluate()


def test_never_ask_completes_every_task_without_questions(domain):
    for task in domain.tasks:
        env = Env(domain, task=task.id, seed=3)
        env.reset()
        execute(env, defaults(domain, all_recipes(domain, task)))
        assert env.evaluate().completed == task.components, task.id
        assert env.world.questions == 0
        assert env.world.trace[-1].text == "Declare Done"


def test_agents_look_before_they_use(domain):
    env = Env(domain, task="cereal", seed=1)
    env.reset()
    play("never-ask", env)
    seen_look = False
    for e in env.world.trace:
        seen_look |= e.text.startswith("Look for")
        if e.text.startswith(("Pour", "Move")):
            assert seen_look
    assert all(e.ok for e in env.world.trace)


def test_oracle_satisfies_what_never_ask_misses(domain):
    _, never = _run(domain, "never-ask")
    _, oracle = _run(domain, "oracle")
    assert oracle.satisfied == 3 and oracle.violated == 0
    assert never.satisfied < oracle.satisfied


def test_always_ask_asks_and_follows_answers(domain):
    env, ev = _run(domain, "always-ask")
    assert ev.questions > 5
    assert {v.id for v in ev.verdicts if v.verdict == "satisfied"} >= {"oat", "patio"}


def test_interpret_answers(domain):
    milk = next(c for c in domain.recipe["cereal"].choices if c.id == "milk")
    assert interpret(domain, milk, "I like oat milk, it is plant-based.") == "oat_milk"
    assert interpret(domain, milk, "No milk for me, I eat it dry.") == "none"
    assert interpret(domain, milk, "I don't mind.") == milk.default[0]
    toppings = next(c for c in domain.recipe["cereal"].choices if c.id == "toppings")
    assert set(interpret(domain, toppings, "Strawberries and walnuts please")) >= {"strawberry", "raw_walnuts"}


def test_interpret_reads_a_negation_to_the_end_of_its_list_and_not_past_its_exception(domain):
    """What a person at the table would serve: nothing the answer's negated list names (its class or the
    item), the exception of "other than", and the default for an answer that rules nothing out."""
    choice = {c.id: c for r in ("cereal", "eggs") for c in domain.recipe[r].choices}
    toppings, milk, seasoning, fat = choice["toppings"], choice["milk"], choice["seasoning"], choice["fat"]
    assert interpret(domain, toppings, "No toppings like fruit or nuts on my sweet breakfasts, please.") == ()
    assert interpret(domain, milk, "For cereal please use dairy milk, not a nut-based milk like almond milk.") \
        == "whole_milk"
    assert interpret(domain, milk, "I only drink dairy milk, please no plant-based milks.") == "whole_milk"
    assert set(interpret(domain, seasoning, "No spices other than salt and pepper on my eggs.")) \
        == {"salt", "pepper"}
    assert "butter" not in str(interpret(domain, fat, "Please don't use butter on toast or in cooking."))
    assert interpret(domain, milk, "I don't have a particular preference about that.") == milk.default[0]
    assert set(interpret(domain, toppings, "No fruit except kiwi, please.")) == {"kiwi"}


def test_a_component_without_recipe_is_said_not_skipped_silently(domain, capsys):
    import dataclasses

    from adaptbench.agents.plans import notes
    from adaptbench.agents.scripted import NeverAsk

    d = dataclasses.replace(domain, recipes=tuple(r for r in domain.recipes if r.id != "toast"))
    task = d.task["toast_coffee"]
    assert notes(d, task) == ["no recipe for component toast: the scripted agents skip it"]
    assert list(NeverAsk(d).notes(task.id)) == notes(d, task) and notes(domain, task) == []
    persona = _zed(d)
    env = Env(d, task="toast_coffee", persona=persona, seed=0, user=OfflineUser(d, persona, task))
    env.reset()
    play("never-ask", env)
    play("never-ask", env)
    err = capsys.readouterr().err
    assert err.count("no recipe for component toast") == 1  # once per domain, on stderr


def test_oracle_ask_asks_where_its_plan_departs_from_the_defaults_then_acts_as_the_oracle(domain):
    env, ev = _run(domain, "oracle-ask")
    plain, oracle = _run(domain, "oracle")
    task = domain.task["toast_coffee"]
    best = Oracle(domain, task, _zed(domain), 0, False).search()
    expected = departures(domain, best, choice_points(domain, all_recipes(domain, task)))
    asked = [e.text[5:-1] for e in env.world.trace if e.text.startswith("Ask ")]
    # oat milk in coffee, the patio, the drink first: three choices only the persona could tell
    assert sorted(asked) == sorted(set(expected)) and len(asked) == 3, asked
    assert env.world.trace[0].text.startswith("Ask ")  # planning choices (where, drink first) before anything else
    assert [e.text for e in env.world.trace if not e.text.startswith("Ask ")] == [e.text for e in plain.world.trace]
    assert ev.satisfied == oracle.satisfied == 3 and ev.questions == 3
    never_env, _ = _run(domain, "never-ask")
    assert not any(e.text.startswith("Ask ") for e in never_env.world.trace)
