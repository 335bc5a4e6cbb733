"""Turning action text into a bound, checked action: template matching, slot binding with
did-you-mean, and preconditions compiled from the spec's rules."""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass

from ..compiler import ast as A
from ..compiler.model import ActionSpec, CompiledDomain
from ..compiler.predicates import evaluators
from ..errors import AdaptError
from .classes import entity_matcher, node_matcher
from .world import Node, World


class ActionFailed(AdaptError):
    """An action could not run; the message is the observation the agent gets."""


@dataclass
class Ref:
    """A bound slot value: an entity id, or a content name with the entity holding it."""

    kind: str  # entity | content
    value: str
    holder: str | None = None

    def __str__(self) -> str:
        return self.value


_SLOT_PATTERNS = {"query": r"(.+?)", "question": r"(.+)"}
_WORD = r"(\S+)"


@dataclass(frozen=True)
class Template:
    """One compiled surface form of an action."""

    action: ActionSpec
    regex: re.Pattern
    slots: tuple


def compile_templates(domain: CompiledDomain) -> tuple[dict, list]:
    """Templates indexed by their first literal word (lower case), plus those starting with a slot."""
    by_word: dict[str, list] = {}
    open_start: list = []
    for action in domain.actions:
        types = dict(action.slots)
        for form in action.forms:
            parts = re.split(r"(\{\w+\})", form)
            pattern, slots = "", []
            for part in parts:
                m = re.fullmatch(r"\{(\w+)\}", part)
                if m:
                    slots.append(m.group(1))
                    pattern += _SLOT_PATTERNS.get(types[m.group(1)], _WORD)
                else:
                    pattern += re.escape(part).replace(r"\ ", r"\s+")
            t = Template(action, re.compile(rf"^{pattern}$", re.IGNORECASE), tuple(slots))
            first = parts[0].split()[0].lower() if parts[0].strip() else None
            (by_word.setdefault(first, []) if first else open_start).append(t)
    return by_word, open_start


def match(templates: tuple, text: str) -> tuple[ActionSpec, dict] | None:
    """The action and raw slot strings `text` matches, or None."""
    by_word, open_start = templates
    first = text.split(maxsplit=1)[0].lower() if text.strip() else ""
    for t in by_word.get(first, []) + open_start:
        m = t.regex.match(text)
        if m:
            return t.action, dict(zip(t.slots, m.groups(), strict=True))
    return None


# ------------------------------------------------------------------ binding
def bind(world: World, action: ActionSpec, raw: dict) -> dict:
    """Resolve raw slot strings to Refs (or strings); raise ActionFailed with a suggestion."""
    types = dict(action.slots)
    out = {}
    for name, value in raw.items():
        out[name] = _bind_one(world, types[name], value)
    return out


def _bind_one(world: World, typ: str, value: str):
    if typ in ("query", "question"):
        return value.strip()
    if typ == "verb":
        verb = value.lower()
        if verb not in world.domain.verbs:
            raise ActionFailed(f"'{value}' is not a verb I know{_suggest(verb, world.domain.verbs)}")
        return verb
    value = value.strip().strip(".,").lower()
    if typ == "result":
        return _fresh_name(world, value)
    if typ in ("entity", "thing") and value in world.known:
        return Ref("entity", value)
    if typ in ("content", "thing") and value in world.known_contents:
        return Ref("content", value)
    pool = set(world.known) | (world.known_contents if typ != "entity" else set())
    what = {"entity": "object", "content": "content", "thing": "object or content"}[typ]
    raise ActionFailed(f"There is no {what} called '{value}' that you have found{_suggest(value, pool)}; "
                       "use Look for or Search to find things")


def _fresh_name(world: World, value: str) -> str:
    if not re.fullmatch(r"[a-z][a-z0-9_]*", value):
        raise ActionFailed(f"'{value}' is not a valid name: use lower-case letters, digits and underscores")
    if value in world.specs:
        raise ActionFailed(f"the name '{value}' is already taken by an object: choose another name")
    return value


def _suggest(word: str, pool) -> str:
    close = difflib.get_close_matches(word, sorted(pool), n=3, cutoff=0.6)
    return f" (did you mean {', '.join(close)}?)" if close else ""


def resolve_holders(world: World, action: ActionSpec, b: dict) -> None:
    """Give every content Ref a holder: the action's source slot, else the one place holding it."""
    for eff in action.effects:
        item, source = eff.param("item"), eff.param("source")
        if item and source:
            ref, src = b.get(item.strip("{}")), b.get(source.strip("{}"))
            if isinstance(ref, Ref) and ref.kind == "content" and isinstance(src, Ref):
                ref.holder = src.value
    for ref in b.values():
        if isinstance(ref, Ref) and ref.kind == "content" and ref.holder is None:
            ref.holder = _only_holder(world, ref.value)


def _only_holder(world: World, name: str) -> str:
    holders = world.holders_of(name)
    finite = [h for h in holders if any(n.name == name for n in world.contents.get(h, ()))]
    pick = finite or holders
    if len(pick) == 1:
        return pick[0]
    if not pick:
        raise ActionFailed(f"no {name} is left anywhere you have looked")
    raise ActionFailed(f"{name} is in several places ({', '.join(pick)}): name the container, "
                       f"e.g. Move {name} from {pick[0]} to ...")


# ------------------------------------------------------------------ preconditions
def compile_check(rule: A.Rule, slot_types: dict):
    """Compile a precondition rule to `f(world, bindings) -> bool`."""
    return _expr(rule.expr, slot_types)


def _expr(node, types: dict):
    if isinstance(node, A.Const):
        return lambda w, b: node.value
    if isinstance(node, A.Not):
        f = _expr(node.item, types)
        return lambda w, b: not f(w, b)
    if isinstance(node, A.AllOf):
        fs = [_expr(x, types) for x in node.items]
        return lambda w, b: all(f(w, b) for f in fs)
    if isinstance(node, A.AnyOf):
        fs = [_expr(x, types) for x in node.items]
        return lambda w, b: any(f(w, b) for f in fs)
    if isinstance(node, A.IfElse):
        c, t, e = (_expr(x, types) for x in (node.cond, node.then, node.other))
        return lambda w, b: t(w, b) if c(w, b) else e(w, b)
    return _PRED[node.op](node, types)


def _slot_cls(cls, types: dict):
    """Entity matcher where a name that is a slot means the entity bound to it."""
    if isinstance(cls, A.ClsName) and cls.name in types:
        name = cls.name
        return lambda w, e, b: isinstance(b.get(name), Ref) and b[name].value == e
    if isinstance(cls, A.ClsAny | A.ClsAll):
        fs = [_slot_cls(x, types) for x in cls.items]
        agg = any if isinstance(cls, A.ClsAny) else all
        return lambda w, e, b: agg(f(w, e, b) for f in fs)
    if isinstance(cls, A.ClsNeg):
        f = _slot_cls(cls.item, types)
        return lambda w, e, b: not f(w, e, b)
    f = entity_matcher(cls)
    return lambda w, e, b: f(w, e)


def holder(world: World, ref: Ref) -> str | None:
    """Where a bound thing is: an entity's holder, or the container holding a content."""
    return ref.holder if ref.kind == "content" else world.parent.get(ref.value)


def content_node(world: World, ref: Ref) -> Node:
    """A node standing for a content Ref (an existing portion, else the substance itself)."""
    for n in world.contents.get(ref.holder, ()):
        if n.name == ref.value:
            return n
    s = world.domain.substance.get(ref.value)
    if s is None:
        return Node(0, ref.value, None, frozenset(world.domain.engine.result_tags))
    return Node(0, s.id, s.category, frozenset(s.tags))


def _p_is(node: A.Pred, types: dict):
    subj = node.subject
    if types.get(subj) == "verb":
        groups = {n.name for n in A.walk(node.args[0]) if isinstance(n, A.ClsName)}
        return lambda w, b: w.domain.verbs.get(b[subj]) in groups
    ent = _slot_cls(node.args[0], types)
    item = node_matcher(node.args[0])

    def check(w, b):
        ref = b[subj]
        if ref.kind == "entity":
            return ent(w, ref.value, b) or (ref.value in w.nodes and item(w.nodes[ref.value], False, False))
        return item(content_node(w, ref), False, False)
    return check


def _p_contains(node: A.Pred, types: dict):
    outer, inner = node.subject, node.args[0]

    def check(w, b):
        o, i = b[outer], b[inner]
        if i.kind == "entity":
            return w.parent.get(i.value) == o.value
        return w.has_content(o.value, i.value)
    return check


def _p_on(node: A.Pred, types: dict):
    subj, f = node.subject, _slot_cls(node.args[0], types)

    def check(w, b):
        h = holder(w, b[subj])
        return h is not None and f(w, h, b)
    return check


def _p_within(node: A.Pred, types: dict):
    subj, f = node.subject, _slot_cls(node.args[0], types)

    def check(w, b):
        ref = b[subj]
        h = holder(w, ref)
        if h is None:
            return False
        return f(w, h, b) or any(f(w, a, b) for a in w.ancestors(h))
    return check


def _p_holds(node: A.Pred, types: dict):
    subj = node.subject
    ent, item = entity_matcher(node.args[0]), node_matcher(node.args[0])

    def check(w, b):
        eid = b[subj].value
        if any(item(n, False, False) for n in w.contents.get(eid, ())):
            return True
        for s in w.sources.get(eid, ()):
            sub = w.domain.substance[s]
            if item(Node(0, s, sub.category, frozenset(sub.tags)), False, False):
                return True
        return any(ent(w, c) for c in w.children.get(eid, ()))
    return check


_PRED = evaluators("precondition", {"is": _p_is, "contains": _p_contains, "on": _p_on, "within": _p_within,
                                    "holds": _p_holds})
