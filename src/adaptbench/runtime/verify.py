"""Preference verifiers: rules evaluated on the episode to satisfied / violated / inapplicable.

Each verdict carries a reason and the steps that decided it. A preference about a component the
task has but the episode did not complete is violated (the paper's rule).
Score = satisfied / (satisfied + violated).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

from ..compiler import ast as A
from ..compiler.model import CompiledDomain, Task
from ..compiler.predicates import evaluators
from .classes import entity_matcher, node_matcher, render
from .dishes import Dish, table
from .styles import process_ok
from .tables import domain_tables
from .world import Node, World


@dataclass(frozen=True)
class Outcome:
    """A predicate's result, why, and the steps that decided it."""

    ok: bool
    why: str
    steps: tuple = ()
    progress: float = -1.0  # how close to holding, in [0, 1] (search agents use it); -1 = 1 if ok else 0

    @property
    def closeness(self) -> float:
        """`progress`, defaulting to 1.0 when the predicate holds and 0.0 when not."""
        return self.progress if self.progress >= 0 else float(self.ok)


@dataclass(frozen=True)
class Verdict:
    """One preference's verdict."""

    id: str
    text: str
    verdict: str  # satisfied | violated | inapplicable
    reason: str
    steps: tuple = ()
    progress: float = 0.0  # for violated verdicts: how close the episode came (0..1)


@dataclass(frozen=True)
class Evaluation:
    """All verdicts of an episode, the satisfaction rate and the questions asked."""

    verdicts: tuple
    questions: int
    completed: tuple  # components of the task that were completed

    @property
    def satisfied(self) -> int:
        """Number of satisfied preferences."""
        return sum(v.verdict == "satisfied" for v in self.verdicts)

    @property
    def violated(self) -> int:
        """Number of violated preferences."""
        return sum(v.verdict == "violated" for v in self.verdicts)

    @property
    def satisfaction_rate(self) -> float | None:
        """p+ / (p+ + p-), or None when no preference applied."""
        n = self.satisfied + self.violated
        return self.satisfied / n if n else None

    def as_dict(self) -> dict:
        """JSON-friendly form."""
        return {"preferences": [{"id": v.id, "text": v.text, "verdict": v.verdict, "reason": v.reason,
                                 "steps": list(v.steps)} for v in self.verdicts],
                "satisfaction_rate": self.satisfaction_rate, "questions": self.questions,
                "completed": list(self.completed)}


class Ctx:
    """Everything a rule can look at, computed once per evaluation."""

    def __init__(self, domain: CompiledDomain, world: World, task: Task):
        self.domain, self.world, self.task = domain, world, task
        self.task_components = set(task.components)
        self.table = table(world)
        self.dishes = [d for d in self.table if not d.as_is]
        self.meal_sides = True  # `sides` means every side at the meal's places (`for all`), else it's sides
        self._done: dict = {}  # (dish key, component) -> completes?
        self._placed: dict = {}  # dish key -> the pieces placed on it, as a dish of their own
        self._kinds: dict = {}  # (dish key, component) -> sweet | savory | beverage
        self._sides: dict = {}  # dish keys (or None) -> their sides
        self._vessels: dict = {}  # class expression -> the scene's entities it matches (for `free`)

    def completes(self, dish: Dish, comps) -> bool:
        """Whether a dish completes any of the components (each checked once, on demand)."""
        for c in comps:
            key = (dish.key, c)
            hit = self._done.get(key)
            if hit is None:
                hit = self._done[key] = compiled(self.domain, self.domain.component[c].completion)(self, [dish]).ok
                if hit:
                    dish.completes.add(c)
            if hit:
                return True
        return False

    def sides(self, dishes: list | None) -> list:
        """What is served alongside `dishes` (None: alongside the meal's dishes) at the same dining place:
        other food in its own vessel, condiments or milk in their containers, pieces placed on the plate."""
        memo = None if dishes is None else tuple(d.key for d in dishes)
        hit = self._sides.get(memo)
        if hit is not None:
            return hit
        if dishes is None:
            dishes = [d for d in self.dishes if self.completes(d, self.task_components)] or self.dishes
        places = {d.place for d in dishes}
        keys = {d.key for d in dishes}
        out = [d for d in self.table if d.place in places and d.key not in keys
               and (d.as_is or not self.completes(d, self.task_components))]
        out += [self._placed_on(d) for d in dishes if d.placed]
        self._sides[memo] = out
        return out

    def _placed_on(self, dish: Dish) -> Dish:
        hit = self._placed.get(dish.key)
        if hit is None:
            hit = self._placed[dish.key] = Dish(f"{dish.key} (placed on it)", dish.container, dish.place,
                                                dish.served_step, list(dish.placed))
        return hit

    def expand(self, name: str) -> set:
        """Component ids a component or group name stands for."""
        return set(self.domain.groups.get(name, (name,)))

    def subject(self, name: str, it: list) -> list:
        """The dishes a subject word means."""
        if name == "it":
            return it
        if name == "meal":
            return self.dishes
        if name == "sides":
            return self.sides(None if self.meal_sides or not it else it)
        comps = self.expand(name) & self.task_components or self.expand(name)
        return [d for d in self.dishes if any(self.completes(d, (c,)) and self.kind_ok(d, c, (name,)) for c in comps)]

    def kind(self, dish: Dish, comp: str) -> str:
        """The kind (sweet, savory, beverage) of a dish of `comp`: toast with jam is sweet."""
        key = (dish.key, comp)
        hit = self._kinds.get(key)
        if hit is None:
            c = self.domain.component[comp]
            alt = c.alt_when is not None and compiled(self.domain, c.alt_when)(self, [dish]).ok
            hit = self._kinds[key] = c.alt_kind if alt else c.kind
        return hit

    def kind_ok(self, dish: Dish, comp: str, targets) -> bool:
        """Whether a dish of `comp` is among `targets` (a kind target asks the dish's own kind)."""
        c = self.domain.component[comp]
        food = self.domain.engine.food_kinds
        if c.alt_kind is None or any(comp in self.expand(t) for t in targets if t not in food):
            return True
        return self.kind(dish, comp) in targets


def compiled(domain: CompiledDomain, rule: A.Rule, part: str = "expr"):
    """A rule's expression (or its scope condition, `part="cond"`) compiled to `f(ctx, it) -> Outcome`.

    Cached in the domain's tables (a bounded LRU keyed by the rule object).
    """
    node = rule.expr if part == "expr" else rule.scope.cond
    return domain_tables(domain).rules.get_or_build(rule, lambda: _expr(node, domain), part)


def _expr(node, domain):
    if isinstance(node, A.Const):
        return lambda ctx, it: Outcome(node.value, "always" if node.value else "never")
    if isinstance(node, A.Not):
        f = _expr(node.item, domain)

        def neg(ctx, it):
            r = f(ctx, it)
            return Outcome(not r.ok, ("not: " if r.ok else "") + r.why, r.steps)
        return neg
    if isinstance(node, A.AllOf):
        fs = [_expr(x, domain) for x in node.items]
        return lambda ctx, it: _all(f(ctx, it) for f in fs)
    if isinstance(node, A.AnyOf):
        fs = [_expr(x, domain) for x in node.items]
        return lambda ctx, it: _any([f(ctx, it) for f in fs])
    if isinstance(node, A.IfElse):
        c, t, e = (_expr(x, domain) for x in (node.cond, node.then, node.other))
        return lambda ctx, it: t(ctx, it) if c(ctx, it).ok else e(ctx, it)
    if isinstance(node, A.Each):
        return _each(node, domain)
    return _PREDS[node.op](node, domain)


def _each(node: A.Each, domain):
    """`each S [with X] (expr)`: every dish of S (having an X) satisfies expr on its own."""
    body = _expr(node.expr, domain)
    f = node_matcher(node.cls) if node.cls is not None else None
    which = f"{node.subject} with {render(node.cls)}" if f else node.subject

    def each(ctx, it):
        dishes = ctx.subject(node.subject, it)
        if f is not None:
            dishes = [d for d in dishes if any(f(n, h, c) for n, h, c in d.leaves)]
        if not dishes:
            return Outcome(True, f"no {which} served")
        return _all(body(ctx, [d]) for d in dishes)
    return each


def _all(outcomes) -> Outcome:
    outcomes = list(outcomes)
    progress = sum(r.closeness for r in outcomes) / len(outcomes)
    for r in outcomes:
        if not r.ok:
            return Outcome(False, r.why, r.steps, progress)
    steps = {s for r in outcomes for s in r.steps}
    return Outcome(True, "; ".join(r.why for r in outcomes if r.why), tuple(sorted(steps)))


def _any(outcomes: list) -> Outcome:
    for r in outcomes:
        if r.ok:
            return r
    return Outcome(False, " and ".join(r.why for r in outcomes if r.why),
                   tuple(sorted({s for r in outcomes for s in r.steps})), max(r.closeness for r in outcomes))


def _label(dishes: list, subject: str = "") -> str:
    return ", ".join(d.key for d in dishes) or (f"no {subject} dish" if subject else "no dish")


def _matches(dishes: list, f, part: str = "leaves"):
    return [(d, n) for d in dishes for n, h, c in getattr(d, part) if f(n, h, c)]


def _presence(node: A.Pred, part: str = "leaves"):
    """`f(ctx, it) -> (hits, found, steps, absent)`: ingredients of the subject's dishes matching the
    class, why (when found / when absent), and the steps they arrived at. Shared by has and has no
    (`part` = "made" / "topped" for made with / topped with)."""
    f, text = node_matcher(node.args[0]), render(node.args[0])

    def look(ctx, it):
        dishes = ctx.subject(node.subject, it)
        hits = _matches(dishes, f, part)
        if hits:
            d, n = hits[0]
            return hits, f"{d.key} has {n.name} ({text})", tuple(sorted({x.arrived for _, x in hits})), ""
        absent = (f"{_label(dishes, node.subject)} has no {text}" if dishes
                  else f"no {node.subject} dish was served (wanted one with {text})")
        return hits, "", (), absent
    return look


def _p_has(node: A.Pred, domain, part: str = "leaves"):
    look = _presence(node, part)

    def has(ctx, it):
        hits, found, steps, absent = look(ctx, it)
        return Outcome(True, found, steps) if hits else Outcome(False, absent)
    return has


def _p_made_with(node: A.Pred, domain):
    return _p_has(node, domain, "made")


def _p_topped_with(node: A.Pred, domain):
    return _p_has(node, domain, "topped")


def _p_made_by(node: A.Pred, domain):
    group = node.args[0].name
    verbs = domain.process.get(group, frozenset())
    return _every_dish(node, lambda ctx, d: any(n.verb in verbs for n in d.derived), f"made by {group}")


def _p_has_no(node: A.Pred, domain):
    look = _presence(node)

    def has_no(ctx, it):
        hits, found, steps, absent = look(ctx, it)
        return Outcome(False, found, steps, 0.5 / len(hits)) if hits else Outcome(True, absent)
    return has_no


def _p_has_only(node: A.Pred, domain):
    f, text = node_matcher(node.args[0]), render(node.args[0])

    def has_only(ctx, it):
        dishes = ctx.subject(node.subject, it)
        bad = [(d, n) for d in dishes for n, h, c in d.leaves if not f(n, h, c)]
        if bad:
            d, n = bad[0]
            return Outcome(False, f"{d.key} has {n.name}, which is not {text}", (n.arrived,))
        return Outcome(True, f"{_label(dishes)} has only {text}")
    return has_only


_CMP = {">=": int.__ge__, "<=": int.__le__, "==": int.__eq__, ">": int.__gt__, "<": int.__lt__}


def _p_count(node: A.Pred, domain):
    cls, op, n = node.args
    f, text, cmp = node_matcher(cls), render(cls), _CMP[op]

    def count(ctx, it):
        dishes = ctx.subject(node.subject, it)
        kinds = sorted({x.category or x.name for _, x in _matches(dishes, f)})
        ok = cmp(len(kinds), n)
        progress = min(len(kinds) / n, 1.0) if op in (">=", ">") and n else float(ok)
        return Outcome(ok, f"{len(kinds)} kind(s) of {text} ({', '.join(kinds) or 'none'}), want {op} {n}",
                       (), progress)
    return count


def _style_ok(ctx: Ctx, dish: Dish, style) -> bool:
    """A style holds by its rule and its process (spec/tasks/styles.yaml), never by a name."""
    if style.rule is not None and not compiled(ctx.domain, style.rule)(ctx, [dish]).ok:
        return False
    if style.process:
        return process_ok(ctx.domain, dish.tops, style.process)
    return style.rule is not None


def _p_is(node: A.Pred, domain):
    names = [n.name for n in A.walk(node.args[0]) if isinstance(n, A.ClsName)]
    text = " or ".join(names)

    def is_(ctx, it):
        dishes = ctx.subject(node.subject, it)
        styles = [ctx.domain.style[s] for s in names]
        bad = [d for d in dishes if not any(_style_ok(ctx, d, s) for s in styles)]
        if bad or not dishes:
            return Outcome(False, f"{_label(bad or dishes)} is not {text}")
        return Outcome(True, f"{_label(dishes)} is {text}")
    return is_


def _every_dish(node: A.Pred, test, describe: str):
    def check(ctx, it):
        dishes = ctx.subject(node.subject, it)
        bad = [d for d in dishes if not test(ctx, d)]
        if bad or not dishes:
            progress = 1 - len(bad) / len(dishes) if dishes else 0.0
            return Outcome(False, f"{_label(bad or dishes)} not {describe}", tuple(d.served_step for d in bad),
                           progress)
        return Outcome(True, f"{_label(dishes)} {describe}", tuple(d.served_step for d in dishes))
    return check


def _p_served_at(node: A.Pred, domain):
    f = entity_matcher(node.args[0])
    return _every_dish(node, lambda ctx, d: f(ctx.world, d.place), f"served at {render(node.args[0])}")


def _p_served_in(node: A.Pred, domain):
    f = entity_matcher(node.args[0])
    return _every_dish(node, lambda ctx, d: d.container is not None and f(ctx.world, d.container),
                       f"served in {render(node.args[0])}")


def _p_made_in(node: A.Pred, domain):
    f = entity_matcher(node.args[0])
    return _every_dish(node, lambda ctx, d: any(f(ctx.world, v) for v in d.vessels),
                       f"made in {render(node.args[0])}")


def _p_cooked_in(node: A.Pred, domain):
    f = entity_matcher(node.args[0])

    def test(ctx, d):
        pans = [v for v in d.vessels if v in ctx.world.specs and "cookware" in ctx.world.specs[v].tags]
        return bool(pans) and all(f(ctx.world, v) for v in pans)
    return _every_dish(node, test, f"cooked in {render(node.args[0])}")


def _first(d: Dish, f) -> int | None:
    steps = [n.arrived for n, h, c in d.leaves if f(n, h, c)]
    return min(steps) if steps else None


def _p_adds_before(node: A.Pred, domain):
    fa, fb = node_matcher(node.args[0]), node_matcher(node.args[1])
    ta, tb = render(node.args[0]), render(node.args[1])

    def test(ctx, d):
        a, b = _first(d, fa), _first(d, fb)
        return a is not None and b is not None and a < b
    return _every_dish(node, test, f"with {ta} added before {tb}")


def _p_served_before(node: A.Pred, domain):
    def check(ctx, it):
        first, then = ctx.subject(node.subject, it), ctx.subject(node.args[0], it)
        if not first or not then:
            return Outcome(False, f"nothing served as {node.subject if not first else node.args[0]}")
        a, b = max(d.served_step for d in first), min(d.served_step for d in then)
        why = f"{node.subject} served by step {a}, {node.args[0]} from step {b}"
        return Outcome(a < b, why, (a, b))
    return check


def _p_available(node: A.Pred, domain):
    item, text = node_matcher(node.args[0]), render(node.args[0])
    available = domain_tables(domain).available  # (predicate, scene) -> bool: a property of the scene

    def in_scene(d: CompiledDomain, present) -> bool:
        for eid in present:
            e = d.entity[eid]
            if item(_entity_node(d, eid), False, False):
                return True
            if any(item(_substance_node(d, s), False, False) for s in e.contents):
                return True
        return False

    def check(ctx, it):
        scene = ctx.world.scene
        ok = available.get_or_build(node, lambda: in_scene(ctx.domain, scene.present), scene.scene_id)
        return Outcome(ok, f"{text} is {'' if ok else 'not '}available")
    return check


def _p_free(node: A.Pred, domain):
    """`free X for S`: for every dish of S, another X stood free when the dish's vessel was chosen (the step
    it last began to hold food; a dish without a vessel: the step it was served): present in the scene, not
    the vessel of anything on the table at the end, and not holding food then unless that food stayed in it
    to the end (a bowl that held the beaten eggs was in use; one left with a pinch of salt in it was idle)."""
    f, text = entity_matcher(node.args[0]), render(node.args[0])

    def check(ctx, it):
        dishes = ctx.subject(node.subject, it)
        if not dishes:
            return Outcome(False, f"no {node.subject} dish was served")
        cands = ctx._vessels.get(node.args[0])
        if cands is None:
            w = ctx.world
            taken = {d.container for d in ctx.table if d.container is not None}
            cands = ctx._vessels[node.args[0]] = [e for e in sorted(w.scene.present) if e not in taken and f(w, e)]
        outcomes = []
        for d in dishes:
            hits, when = _free(ctx, d, cands)
            why = (f"{', '.join(hits)} ({text}) free at step {when}, when {d.key}'s vessel was chosen" if hits
                   else f"no {text} free at step {when}, when {d.key}'s vessel was chosen")
            outcomes.append(Outcome(bool(hits), why, (when,)))
        return _all(outcomes)
    return check


def _free(ctx: Ctx, dish: Dish, cands: list) -> tuple:
    """(the free ones among `cands` (matching vessels not serving at the table) for `dish`, the step its
    vessel was chosen)."""
    w = ctx.world
    when = w.filled_at(dish.container) if dish.container is not None else dish.served_step
    hits = [e for e in cands if not (w.held_food(e, when) and not w.holds_food(e))]
    return hits, when


@lru_cache(maxsize=4096)
def _entity_node(domain: CompiledDomain, eid: str) -> Node:
    e = domain.entity[eid]
    return Node(0, eid, e.category, frozenset(e.tags), entity=eid)




@lru_cache(maxsize=1024)
def _substance_node(domain: CompiledDomain, sid: str) -> Node:
    s = domain.substance[sid]
    return Node(0, sid, s.category, frozenset(s.tags))


def _p_uses(node: A.Pred, domain):
    f, text = entity_matcher(node.args[0]), render(node.args[0])
    if node.subject is not None:
        return _every_dish(node, lambda ctx, d: any(f(ctx.world, v) for v in d.vessels), f"uses {text}")

    def check(ctx, it):
        hits = sorted(e for e in ctx.world.used if f(ctx.world, e))
        steps = tuple(ev.step for ev in ctx.world.trace if ev.ok and set(ev.args.values()) & set(hits))
        return Outcome(bool(hits), f"used {', '.join(hits)}" if hits else f"never used {text}", steps)
    return check


def _p_task_has(node: A.Pred, domain):
    name = node.args[0].name

    def check(ctx, it):
        ok = bool(ctx.expand(name) & ctx.task_components)
        return Outcome(ok, f"the task {'has' if ok else 'has no'} {name}")
    return check


def _p_made(node: A.Pred, domain):
    name = node.args[0].name

    def check(ctx, it):
        comps = ctx.expand(name)
        hits = [d for d in ctx.dishes if ctx.completes(d, comps)]
        return Outcome(bool(hits), f"{name} {'served in ' + _label(hits) if hits else 'was not served'}",
                       tuple(d.served_step for d in hits))
    return check


_PREDS = evaluators("verdict", {  # registered by the names declared in compiler/predicates.py
          "has": _p_has, "has_no": _p_has_no, "has_only": _p_has_only, "count": _p_count, "is": _p_is,
          "served_at": _p_served_at, "served_in": _p_served_in, "made_in": _p_made_in,
          "made_with": _p_made_with, "topped_with": _p_topped_with, "made_by": _p_made_by,
          "cooked_in": _p_cooked_in, "adds_before": _p_adds_before, "served_before": _p_served_before,
          "available": _p_available, "free": _p_free, "uses": _p_uses, "task_has": _p_task_has, "made": _p_made})


from .verdicts import evaluate, verdict  # noqa: E402  (preference-level verdicts; re-exported here)

__all__ = ["Ctx", "Evaluation", "Outcome", "Verdict", "compiled", "evaluate", "verdict"]
