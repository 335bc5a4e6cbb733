"""Preference-level verdicts: scope, availability and per-dish conditions, completion, and the
expression per target component (docs/rules.md, *Preference rules: scope and verdicts*)."""

from __future__ import annotations

from ..compiler import ast as A
from ..compiler.model import CompiledDomain, Persona, Task
from .tables import domain_tables
from .verify import Ctx, Evaluation, Outcome, Verdict, compiled
from .world import World


def verdict(ctx: Ctx, pref) -> Verdict:
    """Evaluate one preference on an evaluation context."""
    rule = pref.rule
    targets = rule.scope.targets if rule.scope else ("all",)
    comps = [c for c in ctx.task.components if any(c in ctx.expand(t) for t in targets)]
    if not comps:
        return Verdict(pref.id, pref.text, "inapplicable", f"the task has no {' or '.join(targets)}")
    per_dish = _per_dish_cond(ctx.domain, rule)
    if rule.scope is not None and rule.scope.cond is not None and not per_dish:
        cond = compiled(ctx.domain, rule, "cond")(ctx, [])
        if not cond.ok:
            return Verdict(pref.id, pref.text, "inapplicable", cond.why)
    ctx.meal_sides = "all" in targets
    results, skipped = _results(ctx, rule, comps, per_dish)
    if not results:
        return Verdict(pref.id, pref.text, "inapplicable", skipped)
    progress = sum(r.closeness for r in results) / len(results)
    for r in results:
        if not r.ok:
            return Verdict(pref.id, pref.text, "violated", r.why, r.steps, progress)
    return Verdict(pref.id, pref.text, "satisfied", results[-1].why, results[-1].steps, 1.0)


def _results(ctx: Ctx, rule: A.Rule, comps: list, per_dish: bool) -> tuple:
    """Outcomes per target component; with a per-dish condition, only dishes where it holds count."""
    f = compiled(ctx.domain, rule)
    cond = compiled(ctx.domain, rule, "cond") if per_dish else None
    results, skipped = [], ""
    targets = rule.scope.targets if rule.scope else ("all",)
    for c in comps:
        dishes = [d for d in ctx.dishes if ctx.completes(d, (c,))]
        if not dishes:
            if ctx.domain.component[c].kind in targets or not set(targets) <= set(ctx.domain.engine.food_kinds):
                results.append(Outcome(False, f"{c} was not completed"))
            continue
        dishes = [d for d in dishes if ctx.kind_ok(d, c, targets)]
        if not dishes:
            skipped = f"the {c} served is not {' or '.join(targets)}"
            continue
        if cond is not None:
            held = [d for d in dishes if cond(ctx, [d]).ok]
            if not held:
                skipped = cond(ctx, dishes).why
                continue
            dishes = held
        results.append(f(ctx, dishes))
    return results, skipped


def _per_dish_cond(domain: CompiledDomain, rule: A.Rule) -> bool:
    """Whether the scope condition talks about the dish (`it`, `sides`): then it is checked per dish
    (cached in the domain's tables)."""
    return domain_tables(domain).per_dish.get_or_build(rule, lambda: _condition_per_dish(rule))


def _condition_per_dish(rule: A.Rule) -> bool:
    """`it` is the dish; so is `sides` (its sides) unless the scope is `all`, where `sides` means every side of
    the meal (`for all if meal has milk or sides has milk`: one condition about the whole table)."""
    cond = rule.scope.cond if rule.scope is not None else None
    meal = "all" in rule.scope.targets if rule.scope is not None else True
    return cond is not None and any(isinstance(n, A.Pred) and (n.subject == "it" or (n.subject == "sides" and not meal))
                                    for n in A.walk(cond))


def evaluate(domain: CompiledDomain, world: World, task: Task, persona: Persona | None) -> Evaluation:
    """Evaluate every preference of `persona` on the episode in `world`."""
    ctx = Ctx(domain, world, task)
    verdicts = tuple(verdict(ctx, p) for p in persona.preferences) if persona else ()
    completed = tuple(c for c in task.components if any(ctx.completes(d, (c,)) for d in ctx.dishes))
    return Evaluation(verdicts, world.questions, completed)
