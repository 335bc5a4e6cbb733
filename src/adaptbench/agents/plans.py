"""Executing recipes in the simulator: choices resolved against what the agent has found.

An `Assignment` maps choice keys (`recipe.choice`, or `plan.choice` for planning choices) to a value
(single choices) or a tuple of values (multi choices). `execute` turns an assignment into actions,
looking for things before it first uses them and falling back to the next option when the chosen
one is not in the house.
"""

from __future__ import annotations

import re
import sys

from ..compiler.model import CompiledDomain, Recipe, Task
from ..runtime.env import Env

PLAN = "plan"
_VAR = re.compile(r"\{(src:)?(\w+)\}")
_ADD = re.compile(r"^ADD (\S+) TO (\S+)$")


def choice_points(domain: CompiledDomain, recipes: list) -> list:
    """(key, Choice) for the planning choices and every choice of the given recipes."""
    out = [(f"{PLAN}.{c.id}", c) for c in domain.planning]
    for r in recipes:
        out += [(f"{r.id}.{c.id}", c) for c in r.choices]
    return out


def defaults(domain: CompiledDomain, recipes: list) -> dict:
    """The never-ask assignment: every choice at its default."""
    return {k: (c.default if c.multi else c.default[0]) for k, c in choice_points(domain, recipes)}


def task_recipes(domain: CompiledDomain, task: Task, assignment: dict | None = None) -> list:
    """Recipes for the task's components, then chosen extras (in the order served)."""
    by_component = {r.component: r for r in domain.recipes if r.component and not r.optional}
    recipes = [by_component[c] for c in task.components if c in by_component]
    extras = (assignment or {}).get(f"{PLAN}.extras", ())
    for rid in extras:
        r = domain.recipe.get(rid)
        if r is not None and r not in recipes:
            recipes.append(r)
    recipes += [r for r in domain.recipes if r.optional]
    return _order(domain, recipes, (assignment or {}).get(f"{PLAN}.serve_order", "as_listed"))


def missing_recipes(domain: CompiledDomain, task: Task) -> tuple:
    """The task's components that no recipe makes (the compiler warns about them, D410)."""
    made = {r.component for r in domain.recipes if r.component and not r.optional}
    return tuple(c for c in task.components if c not in made)


def notes(domain: CompiledDomain, task: Task) -> list:
    """What a scripted agent cannot do on this task, in words (`no recipe for component X`)."""
    return [f"no recipe for component {c}: the scripted agents skip it" for c in missing_recipes(domain, task)]


def _say_missing(domain: CompiledDomain, task: Task) -> None:
    """Print each `no recipe for component X` once per domain to stderr."""
    said = domain.derived("plans.said_missing", lambda d: set())
    for line in notes(domain, task):
        if line not in said:
            said.add(line)
            print(f"adapt: warning: {line} (task {task.id})", file=sys.stderr)


def all_recipes(domain: CompiledDomain, task: Task) -> list:
    """Every recipe a plan for this task might use (task components and all extras)."""
    extras = [c for c in domain.planning if c.id == "extras"]
    names = extras[0].values if extras else ()
    return task_recipes(domain, task, {f"{PLAN}.extras": names})


def _order(domain: CompiledDomain, recipes: list, order: str) -> list:
    drinks = domain.engine.drink_kinds

    def drink(r: Recipe) -> bool:
        return r.component is not None and domain.component[r.component].kind in drinks
    if order == "beverages_first":
        return sorted(recipes, key=lambda r: not drink(r))
    if order == "food_first":
        return sorted(recipes, key=drink)
    return recipes


def _by_category(domain: CompiledDomain) -> dict:
    """Substance ids by category (built once per domain, kept with it)."""
    def build(d: CompiledDomain) -> dict:
        table: dict = {}
        for s in d.substances:
            table.setdefault(s.category, []).append(s.id)
        return table
    return domain.derived("plans.by_category", build)


class Executor:
    """Runs an assignment in an env, exploring as it goes."""

    def __init__(self, env: Env, assignment: dict):
        self.env, self.domain, self.assignment = env, env.domain, assignment
        self.looked: set = set()
        self.taken: set = set()
        self.resolved: dict = {}
        self.vessels: dict = {}  # movable entity -> the choice that claimed it (plates, cups, pans)

    # ---- knowledge
    @property
    def world(self):
        """The world (only `known` things are used)."""
        return self.env.world

    def act(self, text: str) -> bool:
        """Step the env unless it is over; True on success."""
        if self.env.done:
            return False
        return self.env.step(text).ok

    def query_for(self, value: str) -> str:
        """The category word to `Look for` a value by."""
        d = self.domain
        if value in d.substance:
            return d.substance[value].category
        if value in d.entity:
            return d.entity[value].category
        return value

    def find(self, value: str) -> bool:
        """Make sure `value` (entity id, substance or category) is known; look for it if needed."""
        if self._known(value):
            return True
        query = self.query_for(value)
        if query not in self.looked:
            self.looked.add(query)
            self.act(f"Look for {query.replace('_', ' ')}")
        return self._known(value)

    def _known(self, value: str) -> bool:
        w, d = self.world, self.domain
        if value in d.entity or value in w.specs:
            return value in w.known
        if value in d.substance:
            return bool(self._holders(value))
        return any(w.specs[e].category == value for e in w.known if e in w.specs and e not in self.taken) or \
            any(self._holders(s) for s in _by_category(d).get(value, ()))

    def _holders(self, substance: str) -> list:
        return self.world.holders_of(substance)

    # ---- choices
    def usable(self, value: str, needs: tuple) -> bool:
        """Whether an option can be used (finding what it needs)."""
        catalogue = value in self.domain.entity or value in self.domain.substance or self._is_category(value)
        items = list(needs) + ([value] if catalogue else [])
        return all(self.find(i) for i in items)

    def _is_category(self, value: str) -> bool:
        return any(c == value for c, _ in self.domain.categories)

    def value(self, recipe: Recipe, name: str):
        """The resolved value of a choice (single: first usable of chosen + fallbacks; multi: usable subset)."""
        choice = recipe.choice.get(name)
        key = f"{recipe.id}.{name}" if choice else f"{PLAN}.{name}"
        if key in self.resolved:
            return self.resolved[key]
        choice = choice or {c.id: c for c in self.domain.planning}[name]
        chosen = self.assignment.get(key, choice.default if choice.multi else choice.default[0])
        needs = {o.value: o.needs for o in choice.options}
        if choice.multi:
            out = tuple(v for v in chosen if v == "none" or self.usable(v, needs.get(v, ())))
        else:
            exclusive = key.split(".")[0] != PLAN  # a plate or cup belongs to one choice only
            order = [v for v in [chosen] + self._fallbacks(choice, chosen)
                     if not (exclusive and not self._reusable(v) and self.vessels.get(v, key) != key)]
            out = next((v for v in order if v == "none" or self.usable(v, needs.get(v, ()))), chosen)
            if exclusive and self._movable(out):
                self.vessels[out] = key
        self.resolved[key] = out
        return out

    def _reusable(self, value: str) -> bool:
        """Cookware is emptied onto a plate before the next recipe runs, so recipes may share a pan."""
        spec = self.domain.entity.get(value)
        return spec is not None and "cookware" in spec.tags

    def _movable(self, value: str) -> bool:
        spec = self.domain.entity.get(value)
        return spec is not None and spec.kind == "movable"

    def _fallbacks(self, choice, chosen: str) -> list:
        """Other options, those of the chosen one's category first (another mug for a missing mug)."""
        cat = self.query_for(chosen)
        others = [v for v in choice.values if v != chosen]
        return [v for v in others if self.query_for(v) == cat] + [v for v in others if self.query_for(v) != cat]

    # ---- steps
    def run_recipe(self, recipe: Recipe) -> None:
        """Execute a recipe and serve its vessel (an optional recipe with nothing chosen does nothing)."""
        if recipe.optional and not any(self._chosen(recipe, c) for c in recipe.choices if c.multi):
            return
        self.run_steps(recipe, recipe.steps, {})
        vessel, place = self.value(recipe, recipe.serve), self.value(recipe, "place")
        if self.find(vessel) and self._holds_food(vessel):
            self.act(f"Move {vessel} to {place}")

    def _chosen(self, recipe: Recipe, choice) -> bool:
        return bool(self.assignment.get(f"{recipe.id}.{choice.id}", choice.default))

    def _holds_food(self, vessel: str) -> bool:
        w = self.world
        return bool(w.contents.get(vessel)) or any(c in w.nodes for c in w.children.get(vessel, ()))

    def run_steps(self, recipe: Recipe, steps, env_vars: dict) -> None:
        """Execute a list of steps."""
        for s in steps:
            if self.env.done:
                return
            if s.kind == "do":
                self.run_template(recipe, s.text, env_vars)
            elif s.kind == "for":
                for item in self.value(recipe, s.over):
                    if item != "none":
                        self.run_steps(recipe, s.body, {**env_vars, "item": item})
            elif all(self._holds(recipe, name, vals) for name, vals in s.cond):
                self.run_steps(recipe, s.body, env_vars)

    def _holds(self, recipe: Recipe, name: str, vals: tuple) -> bool:
        v = self.value(recipe, name)
        present = [x for x in (v if isinstance(v, tuple) else (v,)) if x != "none"]
        if vals == ("any",):
            return bool(present)
        if vals == ("none",):
            return not present
        return any(x in vals for x in present)

    def run_template(self, recipe: Recipe, text: str, env_vars: dict) -> None:
        """Fill a template's variables and run it (ADD expands to Pour/Move)."""
        def fill(m):
            name = m.group(2)
            value = env_vars[name] if name in env_vars else self.value(recipe, name)
            return self.holder(value) if m.group(1) else value
        filled = _VAR.sub(fill, text)
        m = _ADD.match(filled)
        if m:
            self.add(m.group(1), m.group(2))
        elif filled and "None" not in filled:
            self.act(filled)

    def holder(self, substance: str) -> str:
        """A known container holding a substance (finding it first)."""
        self.find(substance)
        holders = self._holders(substance)
        endless = [h for h in holders if substance in self.world.sources.get(h, ())]
        return (endless or holders or ["None"])[0]  # never take it back out of a dish

    def add(self, what: str, vessel: str) -> None:
        """Put an ingredient (substance, object or category) into a vessel."""
        if not self.find(what) or not self.find(vessel):
            return
        if what in self.domain.substance:
            liquid = "liquid" in self.domain.substance[what].tags
            verb = "Pour {} from {} into {}" if liquid else "Move {} from {} to {}"
            self.act(verb.format(what, self.holder(what), vessel))
            return
        eid = what if what in self.world.specs else self._pick(what, vessel)
        if eid is None:
            sub = next((s for s in _by_category(self.domain).get(what, ()) if self._holders(s)), None)
            if sub:
                self.add(sub, vessel)
            return
        self.taken.add(eid)
        self.act(f"Move {eid} to {vessel}")

    def _pick(self, category: str, vessel: str):
        w = self.world
        for e in sorted(w.known):
            if e in w.specs and w.specs[e].category == category and e not in self.taken and w.parent.get(e) != vessel:
                return e
        return None


def execute(env: Env, assignment: dict) -> None:
    """Run a whole plan: each recipe in order, served as it is finished, then Declare Done."""
    _say_missing(env.domain, env.task)
    ex = Executor(env, assignment)
    for recipe in task_recipes(env.domain, env.task, assignment):
        ex.run_recipe(recipe)
    ex.act("Declare Done")
