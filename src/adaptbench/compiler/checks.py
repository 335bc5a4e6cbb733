"""Semantic checks: every reference resolves, every rule names real things in the right context.

Each check reports diagnostics with a code (documented in docs/errors.md) and a did-you-mean.
"""

from __future__ import annotations

import re
from pathlib import Path

from . import ast as A
from .build import Draft
from .diagnostics import did_you_mean
from .engine import check_effect_values, check_engine, check_persona_numbers, check_splits
from .lint import Item, matches
from .model import Where
from .predicates import QUANTIFIERS, ops_for
from .recipes import check_recipe_steps

SLOT_TYPES = ("entity", "content", "thing", "query", "question", "result", "verb")

# primitive -> (required params, optional params); the runtime implements exactly these.
EFFECTS = {
    "reveal_in": ({"place"}, {"intro"}),
    "reveal_category": ({"query"}, set()),
    "set_state": ({"target", "state"}, set()),
    "heat": ({"target"}, set()),
    "heat_all_in": ({"target"}, set()),
    "move": ({"item", "target"}, {"source"}),
    "pour": ({"item", "source", "target"}, set()),
    "combine": ({"container", "result", "verb"}, {"heat"}),
    "transform": ({"item", "result", "verb"}, {"cut", "heat"}),
    "ask": ({"question"}, set()),
    "done": (set(), set()),
}

PRE_OPS = ops_for("precondition")  # each predicate's contexts are declared once, in predicates.py
DISH_OPS = ops_for("dish")
PREF_OPS = ops_for("preference")
DISH_SUBJECTS = {"meal", "sides"}
_SLOT_RE = re.compile(r"\{(\w+)\}")


class Names:
    """The namespaces rules resolve against."""

    def __init__(self, draft: Draft):
        self.classes = set(draft.categories) | set(draft.tags)
        self.classes |= {e.id for e in draft.entities} | {s.id for s in draft.substances}
        self.components = {c.id for c in draft.components}
        kinds = set(draft.engine.kinds) if draft.engine else set()
        self.groups = {"all", "food"} | kinds | {g for c in draft.components for g in c.groups}
        self.styles = {s.id for s in draft.styles}
        self.verb_groups = set(draft.verb_groups) | set(draft.processes)
        self.items = [Item(s.id, s.category, frozenset(s.tags)) for s in draft.substances]
        self.items += [Item(e.id, e.category, frozenset(e.tags), e.id) for e in draft.entities if e.kind != "room"]
        self.vessels = {e.id for e in draft.entities if e.kind == "movable" and "container" in e.tags}
        self.rooms = _rooms(draft.entities)


def _rooms(entities: list) -> dict:
    """Entity id -> the room it is in (for class names that are rooms)."""
    ids = {e.id: e for e in entities}
    out = {}
    for e in entities:
        loc, seen = e, set()
        while loc.location is not None and loc.location in ids and loc.id not in seen:
            seen.add(loc.id)
            loc = ids[loc.location]
        out[e.id] = loc.id
    return out


def check_all(draft: Draft) -> None:
    """Run every semantic check, appending diagnostics to `draft.diags`."""
    names = Names(draft)
    check_objects(draft)
    check_actions(draft, names)
    check_verbs(draft)
    check_tasks(draft, names)
    check_personas(draft, names)
    check_recipes(draft, names)
    check_recipe_steps(draft)
    check_engine(draft)
    check_effect_values(draft)
    check_splits(draft)
    check_persona_numbers(draft)


# ---------------------------------------------------------------- objects
def check_objects(draft: Draft) -> None:
    """Categories, tags, locations and contents of every entity and substance resolve."""
    ids = {e.id: e for e in draft.entities}
    subs = {s.id for s in draft.substances}
    for e in draft.entities:
        if e.kind != "room":
            _check_class_ref(draft, ("entity", e.id), e.category, draft.categories, "category")
            for j, t in enumerate(e.tags):
                if t not in ("furniture", "movable"):
                    _check_class_ref(draft, ("entity", e.id, "tags", j), t, draft.tags, "tag")
        _check_location(draft, e, ids)
        for j, c in enumerate(e.contents):
            if c not in subs:
                where = _where(draft, ("entity", e.id, "contents", j), ("entity", e.id))
                draft.error(where, "D103", f"unknown substance '{c}' in contents{did_you_mean(c, subs)}")
    for s in draft.substances:
        _check_class_ref(draft, ("substance", s.id), s.category, draft.categories, "category")
        for j, t in enumerate(s.tags):
            _check_class_ref(draft, ("substance", s.id, "tags", j), t, draft.tags, "tag")


def _check_class_ref(draft: Draft, key: tuple, name: str, known: dict, what: str) -> None:
    if name in known:
        return
    field_key = key if len(key) > 2 else key + ("category",)
    where = _where(draft, field_key, key[:2])
    draft.error(where, "D101", f"unknown {what} '{name}'{did_you_mean(name, known)}"
                f" (declare it in spec/objects/vocabulary.yaml)")


def _check_location(draft: Draft, e, ids: dict) -> None:
    if e.kind == "room":
        return
    field = "room" if e.kind == "furniture" else "location"
    target = ids.get(e.location)
    ok = target is not None and (target.kind == "room" if e.kind == "furniture" else target.id != e.id)
    if not ok:
        pool = [i for i, x in ids.items() if (x.kind == "room") == (e.kind == "furniture")]
        where = _where(draft, ("entity", e.id, field), ("entity", e.id))
        draft.error(where, "D102", f"unknown {field} '{e.location}'{did_you_mean(e.location, pool)}")


def _where(draft: Draft, key: tuple, fallback: tuple) -> Where:
    return draft.where.get(key) or draft.where.get(fallback) or Where("<spec>", 1, 1)


# ---------------------------------------------------------------- actions
def check_actions(draft: Draft, names: Names) -> None:
    """Slot types, forms, effects and preconditions of every action."""
    for a in draft.actions:
        slots = dict(a.slots)
        for name, typ in a.slots:
            if typ not in SLOT_TYPES:
                draft.error(draft.where[("slot", a.id, name)], "D201",
                            f"unknown slot type '{typ}'{did_you_mean(typ, SLOT_TYPES)}"
                            f" (one of: {', '.join(SLOT_TYPES)})")
        for j, form in enumerate(a.forms):
            used = _SLOT_RE.findall(form)
            for s in used:
                if s not in slots:
                    draft.error(draft.where[("form", a.id, j)], "D202",
                                f"form uses undeclared slot '{{{s}}}'{did_you_mean(s, slots)}")
            for s in slots:
                if s not in used:
                    draft.error(draft.where[("form", a.id, j)], "D202", f"form does not use slot '{{{s}}}'")
        _check_effects(draft, a, slots)
        for p in a.preconditions:
            _check_rule(draft, p.check, "precondition", names, slots=slots)


def _check_effects(draft: Draft, a, slots: dict) -> None:
    for j, eff in enumerate(a.effects):
        where = draft.where[("effect", a.id, j)]
        if eff.primitive not in EFFECTS:
            draft.error(where, "D203", f"unknown effect '{eff.primitive}'{did_you_mean(eff.primitive, EFFECTS)}")
            continue
        required, optional = EFFECTS[eff.primitive]
        given = {k for k, _ in eff.params}
        for k in sorted(required - given):
            draft.error(where, "D203", f"effect '{eff.primitive}' needs parameter '{k}'")
        for k in sorted(given - required - optional):
            draft.error(where, "D203", f"effect '{eff.primitive}' has no parameter '{k}'"
                        f"{did_you_mean(k, required | optional)}")
        for _, v in eff.params:
            for s in _SLOT_RE.findall(v):
                if s not in slots:
                    draft.error(where, "D202", f"effect uses undeclared slot '{{{s}}}'{did_you_mean(s, slots)}")


def check_verbs(draft: Draft) -> None:
    """A verb belongs to one group only; process groups name declared verbs (or the engine's action verbs)."""
    action_verbs = set(draft.engine.action_verbs) if draft.engine else set()
    declared = {v for vs in draft.verb_groups.values() for v in vs} | action_verbs
    for group, verbs in draft.processes.items():
        for v in verbs:
            if v not in declared:
                draft.error(draft.where[("process", group)], "D204",
                            f"process group '{group}' names undeclared verb '{v}'{did_you_mean(v, declared)}")
    seen: dict = {}
    for group, verbs in draft.verb_groups.items():
        for v in verbs:
            if v in seen and seen[v] != group:
                draft.error(draft.where[("verb", v)], "D204", f"verb '{v}' is in both '{seen[v]}' and '{group}'")
            seen.setdefault(v, group)


# ---------------------------------------------------------------- tasks and personas
def check_tasks(draft: Draft, names: Names) -> None:
    """Tasks name real components; completion and style rules are well-formed."""
    for t in draft.tasks:
        for j, c in enumerate(t.components):
            if c not in names.components:
                draft.error(draft.where[("task", t.id, "components", j)], "D105",
                            f"unknown component '{c}'{did_you_mean(c, names.components)}")
    for c in draft.components:
        _check_rule(draft, c.completion, "dish", names)
        if c.alt_when is not None:
            _check_rule(draft, c.alt_when, "dish", names)
        for r in c.requires:
            if r not in names.classes:
                draft.error(draft.where[("component", c.id)], "D104",
                            f"unknown class '{r}' in requires{did_you_mean(r, names.classes)}")
    _check_styles(draft, names)


def _check_styles(draft: Draft, names: Names) -> None:
    for s in draft.styles:
        if s.rule is not None:
            _check_rule(draft, s.rule, "dish", names)
        elif not (s.words or s.verbs or s.process):
            draft.error(draft.where[("style", s.id)], "D110", f"style '{s.id}' needs a process or a rule")
        for alt in s.process:
            _check_process(draft, s.id, dict(alt), names)


def _check_process(draft: Draft, style: str, alt: dict, names: Names) -> None:
    pools = {"food": ("class", names.classes), "with": ("class", names.classes)}
    for key in ("before_heat", "not_before_heat", "while_hot", "not_while_hot", "made_by"):
        pools[key] = ("verb group", names.verb_groups)
    for key, (what, known) in pools.items():
        for name in alt.get(key, "").split("|"):
            name = name.strip()
            if key in alt and name not in known:
                draft.error(draft.where[("style", style)], "D104", f"unknown {what} '{name}' in process of style "
                            f"'{style}'{did_you_mean(name, known)}")


def check_personas(draft: Draft, names: Names) -> None:
    """Persona files are named after their id; every preference rule is well-formed."""
    for p in draft.personas:
        file = draft.where[("persona_file", p.id)]
        if Path(file).stem != p.id:
            draft.error(draft.where[("persona", p.id)], "D302",
                        f"persona id '{p.id}' does not match its file name '{Path(file).name}'")
        for pref in p.preferences:
            _check_rule(draft, pref.rule, "preference", names)


def _check_rule(draft: Draft, rule: A.Rule, context: str, names: Names, slots: dict | None = None) -> None:
    errors: list = []
    if rule.scope is not None:
        if context != "preference":
            errors.append((rule.scope, "D108", "'for ...:' scopes are only allowed in preference rules"))
        for t in rule.scope.targets:
            if t not in names.components | names.groups:
                errors.append((rule.scope, "D105", f"unknown component or group '{t}'"
                               f"{did_you_mean(t, names.components | names.groups)}"))
    for node in A.walk(rule):
        if isinstance(node, A.Pred):
            errors.extend(_check_pred(node, context, names, slots or {}, rule.scope is not None))
        elif isinstance(node, A.Each):
            errors.extend(_check_each(node, context, names, rule.scope is not None))
    for node, code, msg in errors:
        draft.error(Where(rule.file, node.line, node.col), code, msg)


def _check_each(node: A.Each, context: str, names: Names, scoped: bool) -> list:
    if context not in QUANTIFIERS["each"].contexts:
        return [(node, "D108", f"'each' cannot be used in a {context} rule")]
    out = list(_check_subject(node, node.subject, context, names, {}, scoped))
    if node.cls is not None:
        out += _check_cls(node.cls, ("name", names.classes))
    return out


def _check_pred(node: A.Pred, context: str, names: Names, slots: dict, scoped: bool) -> list:
    allowed = {"precondition": PRE_OPS, "dish": DISH_OPS, "preference": PREF_OPS}[context]
    if node.op not in allowed:
        return [(node, "D108", f"'{_op_word(node.op)}' cannot be used in a {context} rule")]
    out = list(_check_subject(node, node.subject, context, names, slots, scoped))
    if node.op == "served_before" or node.op == "contains":
        out += _check_subject(node, node.args[0], context, names, slots, scoped)
        return out
    if node.op in ("task_has", "made"):
        name = node.args[0].name
        pool = names.components | names.groups
        if name not in pool:
            out.append((node.args[0], "D105", f"unknown component or group '{name}'{did_you_mean(name, pool)}"))
        return out
    for arg in node.args:
        if isinstance(arg, A.Node):
            out += _check_cls(arg, _cls_pool(node, context, names, slots))
    if node.op == "free" and not out:
        out += _check_vessels(node.args[0], names)
    return out


def _check_vessels(cls, names: Names) -> list:
    """`free X for S` asks about vessels: X names movable containers (plates, cups, pans), and only them."""
    mod = next((n for n in A.walk(cls) if isinstance(n, A.ClsMod)), None)
    if mod is not None:
        return [(mod, "D112", f"'free' asks about vessels; '{mod.mod}' describes an ingredient: "
                              f"write 'free {A.render_cls(mod.item)} for ...'")]
    text = A.render_cls(cls)
    hits = [i for i in names.items if matches(cls, i, names.rooms)]
    if not hits:
        return [(cls, "D112", f"'free {text} for ...' matches no object a dish could be served or cooked in "
                              f"(e.g. 'fancy & plate', 'cookware & cast_iron')")]
    bad = [i.name for i in hits if i.name not in names.vessels]
    if bad:
        return [(cls, "D112", f"'free {text} for ...' also matches {', '.join(sorted(bad)[:3])}, which "
                              f"{'is' if len(bad) == 1 else 'are'} not a movable container (narrow it, e.g. "
                              f"'{text} & dishware')")]
    return []


def _cls_pool(node: A.Pred, context: str, names: Names, slots: dict) -> tuple:
    if node.op == "made_by":
        return ("verb group", names.verb_groups)
    if node.op == "is" and context != "precondition":
        return ("style", names.styles)
    if node.op == "is" and slots.get(node.subject) == "verb":
        return ("verb group", names.verb_groups)
    if context == "precondition":
        return ("name", names.classes | set(slots))
    return ("name", names.classes)


def _check_cls(cls, pool: tuple) -> list:
    what, known = pool
    out = []
    for n in A.walk(cls):
        if isinstance(n, A.ClsName) and n.name not in known:
            code = "D106" if what == "style" else "D104"
            out.append((n, code, f"unknown {what} '{n.name}'{did_you_mean(n.name, known)}"))
    return out


def _check_subject(node, subject, context: str, names: Names, slots: dict, scoped: bool) -> list:
    if subject is None:
        return []
    if context == "precondition":
        if subject not in slots:
            return [(node, "D107", f"unknown slot '{subject}'{did_you_mean(subject, slots)}")]
        return []
    if subject == "it":
        if context == "preference" and not scoped:
            return [(node, "D109", "'it' needs a scope: write 'for COMPONENT: it ...'")]
        return []
    if context == "dish":
        return [(node, "D107", f"completion and style rules talk about 'it' only, not '{subject}'")]
    pool = names.components | names.groups | DISH_SUBJECTS
    if subject not in pool:
        return [(node, "D105", f"unknown subject '{subject}'{did_you_mean(subject, pool | {'it'})}")]
    return []


def _op_word(op: str) -> str:
    return op.replace("_", " ")


# ---------------------------------------------------------------- recipes


def check_recipes(draft: Draft, names: Names) -> None:
    """Recipes name real components, options that exist, and only their own choices."""
    catalogue = {e.id for e in draft.entities} | {s.id for s in draft.substances}
    for r in draft.recipes:
        where = draft.where[("recipe", r.id)]
        if r.component is not None and r.component not in names.components:
            draft.error(where, "D105", f"unknown component '{r.component}'{did_you_mean(r.component, names.components)}")
        choices = {c.id: c for c in r.choices} | {c.id: c for c in draft.planning}
        if r.serve not in choices:
            draft.error(where, "D403", f"serve '{r.serve}' is not a choice of recipe '{r.id}'")
        for c in r.choices:
            _check_choice(draft, draft.where[("choice", r.id, c.id)], c, catalogue)


def _check_choice(draft: Draft, where: Where, c, catalogue: set) -> None:
    for o in c.options:
        for need in o.needs:
            if need not in catalogue:
                draft.error(where, "D401", f"option '{o.value}' needs unknown '{need}'{did_you_mean(need, catalogue)}")
    for d in c.default:
        if d not in c.values:
            draft.error(where, "D402", f"default '{d}' of choice '{c.id}' is not one of its options")
