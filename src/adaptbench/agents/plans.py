"""Executing recipes in the simulator: choices resolved against what the agent has found.

An `Assignment` maps choice keys (`recipe.choice`, or `plan.choice` for planning choices) to a value
(single choices) or a tuple of values (multi choices). `execute` turns an assignment into actions,
looking for things before it first uses them and falling back to the next option when the chosen
one is not in the house.
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass

from ..compiler.model import CompiledDomain, Recipe, Task
from ..runtime.env import Env
from ..runtime.tables import domain_tables

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
    """Substance ids by category (from the domain's tables, built once per domain)."""
    return domain_tables(domain).substances_by_category


class Executor:
    """Carries out an assignment one action at a time, exploring as it goes.

    `steps()` is a generator: it yields each action's text and is sent back a `Feedback` (whether the
    action succeeded, the user's reply, what the agent has seen since). It reads only what the agent
    has found (`seen`, a `runtime.seen.Seen`)."""

    def __init__(self, domain: CompiledDomain, task: Task, assignment: dict, seen=None):
        self.domain, self.task, self.assignment = domain, task, assignment
        self.seen = seen
        self.looked: set = set()
        self.taken: set = set()
        self.resolved: dict = {}
        self.vessels: dict = {}  # movable entity -> the choice that claimed it (plates, cups, pans)
        self.context: list = []  # the (choice key, value) pairs the action being built realises
        self.serves: tuple = ()  # those of the last action yielded

    def within(self, pairs, steps):
        """Run the generator `steps` with (choice key, value) `pairs` in context: every action it yields
        realises them (`serves`)."""
        pairs = list(pairs)
        self.context.extend(pairs)
        try:
            return (yield from steps)
        finally:
            del self.context[len(self.context) - len(pairs):]

    def steps(self):
        """Every recipe of the plan in order, each served as it is finished, then Declare Done."""
        _say_missing(self.domain, self.task)
        for recipe in task_recipes(self.domain, self.task, self.assignment):
            yield from self.run_recipe(recipe)
        yield from self.act("Declare Done")

    def act(self, text: str):
        """Take one action; True on success (what the agent has seen is refreshed from the feedback).
        `serves` holds the (choice key, value) pairs in context while it is out."""
        self.serves = tuple(dict.fromkeys(self.context))
        feedback = yield text
        self.seen = feedback.seen
        return feedback.ok

    def query_for(self, value: str) -> str:
        """The category word to `Look for` a value by."""
        d = self.domain
        if value in d.substance:
            return d.substance[value].category
        if value in d.entity:
            return d.entity[value].category
        return value

    def find(self, value: str):
        """Make sure `value` (entity id, substance or category) is known; look for it if needed."""
        if self._known(value):
            return True
        query = self.query_for(value)
        if query not in self.looked:
            self.looked.add(query)
            yield from self.act(f"Look for {query.replace('_', ' ')}")
        return self._known(value)

    def _known(self, value: str) -> bool:
        seen, d = self.seen, self.domain
        if value in d.entity or seen.knows(value):
            return seen.knows(value)
        if value in d.substance:
            return bool(seen.holders_of(value))
        return any(seen.category(e) == value for e in seen.known() if e not in self.taken) or \
            any(seen.holders_of(s) for s in _by_category(d).get(value, ()))

    # ---- choices
    def usable(self, value: str, needs: tuple):
        """Whether an option can be used (finding what it needs)."""
        catalogue = value in self.domain.entity or value in self.domain.substance or self._is_category(value)
        for item in list(needs) + ([value] if catalogue else []):
            if not (yield from self.find(item)):
                return False
        return True

    def _is_category(self, value: str) -> bool:
        return any(c == value for c, _ in self.domain.categories)

    def value(self, recipe: Recipe, name: str):
        """The resolved value of a choice (single: first usable of chosen + fallbacks; multi: usable subset)."""
        choice = recipe.choice.get(name)
        key = self.key(recipe, name)
        if key in self.resolved:
            return self.resolved[key]
        choice = choice or {c.id: c for c in self.domain.planning}[name]
        chosen = self.assignment.get(key, choice.default if choice.multi else choice.default[0])
        needs = {o.value: o.needs for o in choice.options}
        if choice.multi:
            out = []
            for v in chosen:
                if v == "none" or (yield from self.within([(key, v)], self.usable(v, needs.get(v, ())))):
                    out.append(v)
            out = tuple(out)
        else:
            exclusive = key.split(".")[0] != PLAN  # a plate or cup belongs to one choice only
            order = [v for v in [chosen] + self._fallbacks(choice, chosen)
                     if not (exclusive and not self._reusable(v) and self.vessels.get(v, key) != key)]
            out = chosen
            for v in order:
                if v == "none" or (yield from self.within([(key, v)], self.usable(v, needs.get(v, ())))):
                    out = v
                    break
            if exclusive and self._movable(out):
                self.vessels[out] = key
        self.resolved[key] = out
        return out

    def key(self, recipe: Recipe, name: str) -> str:
        """The assignment key of a recipe's variable: `recipe.choice`, or `plan.choice` for a planning one."""
        return f"{recipe.id}.{name}" if name in recipe.choice else f"{PLAN}.{name}"

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
    def run_recipe(self, recipe: Recipe):
        """Execute a recipe and serve its vessel (an optional recipe with nothing chosen does nothing)."""
        if recipe.optional and not any(self._chosen(recipe, c) for c in recipe.choices if c.multi):
            return
        yield from self.run_steps(recipe, recipe.steps, {})
        vessel = yield from self.value(recipe, recipe.serve)
        place = yield from self.value(recipe, "place")
        serving = [(self.key(recipe, recipe.serve), vessel), (self.key(recipe, "place"), place)]
        if (yield from self.within(serving, self.find(vessel))) and self.seen.holds_food(vessel):
            yield from self.within(serving, self.act(f"Move {vessel} to {place}"))

    def _chosen(self, recipe: Recipe, choice) -> bool:
        return bool(self.assignment.get(f"{recipe.id}.{choice.id}", choice.default))

    def run_steps(self, recipe: Recipe, steps, env_vars: dict):
        """Execute a list of steps."""
        for s in steps:
            if s.kind == "do":
                yield from self.run_template(recipe, s.text, env_vars)
            elif s.kind == "for":
                for item in (yield from self.value(recipe, s.over)):
                    if item != "none":
                        yield from self.within([(self.key(recipe, s.over), item)],
                                               self.run_steps(recipe, s.body, {**env_vars, "item": item}))
            elif (yield from self._all_hold(recipe, s.cond)):
                held = [(self.key(recipe, name), v) for name, _ in s.cond
                        for v in _values(self.resolved.get(self.key(recipe, name)))]
                yield from self.within(held, self.run_steps(recipe, s.body, env_vars))

    def _all_hold(self, recipe: Recipe, cond):
        for name, vals in cond:
            if not (yield from self._holds(recipe, name, vals)):
                return False
        return True

    def _holds(self, recipe: Recipe, name: str, vals: tuple):
        v = yield from self.value(recipe, name)
        present = [x for x in (v if isinstance(v, tuple) else (v,)) if x != "none"]
        if vals == ("any",):
            return bool(present)
        if vals == ("none",):
            return not present
        return any(x in vals for x in present)

    def run_template(self, recipe: Recipe, text: str, env_vars: dict):
        """Fill a template's variables, left to right, and run it (ADD expands to Pour/Move)."""
        parts, last, used = [], 0, []
        for m in _VAR.finditer(text):
            name = m.group(2)
            value = env_vars[name] if name in env_vars else (yield from self.value(recipe, name))
            if name not in env_vars:
                used += [(self.key(recipe, name), v) for v in _values(value)]
            if m.group(1):
                value = yield from self.within(used, self.holder(value))
            parts += [text[last:m.start()], value]
            last = m.end()
        filled = "".join(parts) + text[last:]
        m = _ADD.match(filled)
        if m:
            yield from self.within(used, self.add(m.group(1), m.group(2)))
        elif filled and "None" not in filled:
            yield from self.within(used, self.act(filled))

    def holder(self, substance: str):
        """A known container holding a substance (finding it first)."""
        yield from self.find(substance)
        holders = self.seen.holders_of(substance)
        endless = [h for h in holders if substance in self.seen.sources(h)]
        return (endless or holders or ["None"])[0]  # never take it back out of a dish

    def add(self, what: str, vessel: str):
        """Put an ingredient (substance, object or category) into a vessel."""
        if not (yield from self.find(what)) or not (yield from self.find(vessel)):
            return
        if what in self.domain.substance:
            liquid = "liquid" in self.domain.substance[what].tags
            verb = "Pour {} from {} into {}" if liquid else "Move {} from {} to {}"
            source = yield from self.holder(what)
            yield from self.act(verb.format(what, source, vessel))
            return
        eid = what if self.seen.knows(what) else self._pick(what, vessel)
        if eid is None:
            sub = next((s for s in _by_category(self.domain).get(what, ()) if self.seen.holders_of(s)), None)
            if sub:
                yield from self.add(sub, vessel)
            return
        self.taken.add(eid)
        yield from self.act(f"Move {eid} to {vessel}")

    def _pick(self, category: str, vessel: str):
        seen = self.seen
        for e in sorted(seen.known()):
            if seen.category(e) == category and e not in self.taken and seen.parent(e) != vessel:
                return e
        return None


def _values(value) -> tuple:
    """A resolved choice value as a tuple of values (a multi choice's tuple, or the single value)."""
    if value is None:
        return ()
    return tuple(value) if isinstance(value, tuple) else (value,)


@dataclass(frozen=True)
class Feedback:
    """What a planner learns from one action: success, the user's reply, and what it has now seen."""

    ok: bool
    reply: str
    seen: object


def feedback(view) -> Feedback:
    """The feedback on the last action of a `harness.policy.View`."""
    last = view.history[-1]
    return Feedback(last.ok, last.reply, view.seen)


def drive(env: Env, steps) -> None:
    """Run a planner's action generator straight against an env, recording nothing: the oracle's
    private simulations while it plans. Benchmark episodes are run by `harness.episode`."""
    try:
        text = next(steps)
        while True:
            result = env.step(text)
            if env.done:
                return
            text = steps.send(Feedback(result.ok, result.reply, env.seen()))
    except StopIteration:
        return


def execute(env: Env, assignment: dict) -> None:
    """Carry out a whole plan straight against an env (see `drive`)."""
    drive(env, Executor(env.domain, env.task, assignment, env.seen()).steps())
