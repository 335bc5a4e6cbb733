"""The persona linter (part of `adapt validate`): applicability matrix, preferences that apply to
no task, class expressions that match nothing in the catalogue, pairs of preferences of one persona
that cannot both be satisfied (also when one or both hold only under an `if` condition), and
preferences that contradict a component's completion rule (no fruit, on a fruit smoothie task)."""

from __future__ import annotations

from dataclasses import dataclass

from . import ast as A
from .diagnostics import Diagnostic
from .model import CompiledDomain, Persona, Preference


@dataclass(frozen=True)
class Item:
    """A catalogue thing as a class expression sees it."""

    name: str
    category: str
    tags: frozenset
    entity: str | None = None


def catalogue_items(domain: CompiledDomain) -> list:
    """Every substance and every edible movable, as matchable items."""
    items = [Item(s.id, s.category, frozenset(s.tags)) for s in domain.substances]
    items += [Item(e.id, e.category, frozenset(e.tags), e.id) for e in domain.entities]
    return items


def matches(cls, item: Item, rooms: dict) -> bool:
    """Whether a class expression matches a catalogue item (modifiers ignored)."""
    if isinstance(cls, A.ClsName):
        n = cls.name
        return n in (item.category, item.name, item.entity) or n in item.tags or rooms.get(item.name) == n
    if isinstance(cls, A.ClsAny):
        return any(matches(x, item, rooms) for x in cls.items)
    if isinstance(cls, A.ClsAll):
        return all(matches(x, item, rooms) for x in cls.items)
    if isinstance(cls, A.ClsNeg):
        return not matches(cls.item, item, rooms)
    return matches(cls.item, item, rooms)


def _rooms(domain: CompiledDomain) -> dict:
    out = {}
    for e in domain.entities:
        loc = e
        while loc.location is not None:
            loc = domain.entity[loc.location]
        out[e.id] = loc.id
    return out


def applies_to(domain: CompiledDomain, pref: Preference, task) -> bool:
    """Whether the preference's scope covers the task (availability aside)."""
    targets = pref.rule.scope.targets if pref.rule.scope else ("all",)
    return any(c in domain.groups.get(t, (t,)) for t in targets for c in task.components)


def matrix(domain: CompiledDomain) -> list:
    """Rows (persona id, [number of applicable preferences per task]) in task order."""
    return [(p.id, [sum(applies_to(domain, pref, t) for pref in p.preferences) for t in domain.tasks])
            for p in domain.personas]


def render_matrix(domain: CompiledDomain) -> str:
    """The applicability matrix as a text table."""
    tasks = [t.id for t in domain.tasks]
    width = max(len(t) for t in tasks)
    head = f"{'persona':<10} " + " ".join(f"{t:>{width}}" for t in tasks) + "  total"
    lines = [head]
    for pid, row in matrix(domain):
        total = len(domain.persona[pid].preferences)
        lines.append(f"{pid:<10} " + " ".join(f"{n:>{width}}" for n in row) + f"  {total:>5}")
    return "\n".join(lines)


def lint(domain: CompiledDomain, where: dict) -> list:
    """Linter diagnostics; `where` maps ("rule", persona, pref) to a Where."""
    items, rooms = catalogue_items(domain), _rooms(domain)
    out: list = []
    for p in domain.personas:
        for pref in p.preferences:
            w = where.get(("rule", p.id, pref.id))
            if w is None:
                continue
            if not any(applies_to(domain, pref, t) for t in domain.tasks):
                out.append(Diagnostic(w.file, w.line, w.col, "L001", f"preference '{pref.id}' applies to no task",
                                      "warning"))
            out += _empty_classes(pref, items, rooms, w.file)
        out += _conflicts(domain, p, where, items, rooms)
        out += _conditional_conflicts(domain, p, where, items, rooms)
        out += _against_completion(domain, p, where, items, rooms)
    return _acknowledge(domain, where, out)


def acknowledged(domain: CompiledDomain) -> list:
    """(persona, preference, code, why) for every linter warning the spec declares expected (`expected_lint`)."""
    return [(p.id, pref.id, code, why) for p in domain.personas for pref in p.preferences
            for code, why in pref.expected_lint]


def _acknowledge(domain: CompiledDomain, where: dict, diags: list) -> list:
    """Drop the warnings a preference's `expected_lint` acknowledges (reported on that preference's rule line);
    an acknowledged warning the linter no longer gives is L006, so stale acknowledgements do not pile up."""
    out, seen = list(diags), set()
    for pid, prid, code, _ in acknowledged(domain):
        w = where.get(("rule", pid, prid))
        if w is None:
            continue
        hit = [d for d in out if d.code == code and d.severity == "warning" and (d.path, d.line) == (w.file, w.line)]
        if hit:
            seen.add((pid, prid, code))
            out = [d for d in out if d not in hit]
        else:
            out.append(Diagnostic(w.file, w.line, w.col, "L006", f"preference '{prid}' declares expected_lint "
                                  f"{code}, which the linter no longer reports: remove it", "warning"))
    return out


def _empty_classes(pref: Preference, items: list, rooms: dict, file: str) -> list:
    out = []
    for node in A.walk(pref.rule):
        if isinstance(node, A.Pred) and node.op not in ("is", "task_has", "made", "served_before"):
            for cls in node.args:
                if isinstance(cls, A.Node) and not any(matches(cls, i, rooms) for i in items):
                    out.append(Diagnostic(file, cls.line, cls.col, "L002",
                                          f"'{_text(cls)}' matches nothing in the catalogue"))
    return out


def _text(cls) -> str:
    return A.render_cls(cls)


def _atoms(pref: Preference) -> list:
    """Top-level conjuncts of a rule's expression."""
    e = pref.rule.expr
    return list(e.items) if isinstance(e, A.AllOf) else [e]


def _scope(pref: Preference) -> tuple:
    return pref.rule.scope.targets if pref.rule.scope else ("all",)


def _covers(domain, a: tuple, b: tuple) -> bool:
    ca = {c for t in a for c in domain.groups.get(t, (t,))}
    cb = {c for t in b for c in domain.groups.get(t, (t,))}
    return bool(ca & cb)


def _conflicts(domain: CompiledDomain, persona: Persona, where: dict, items: list, rooms: dict) -> list:
    out = []
    prefs = [p for p in persona.preferences if p.rule.scope is None or p.rule.scope.cond is None]
    for i, a in enumerate(prefs):
        for b in prefs[i + 1:]:
            if not _covers(domain, _scope(a), _scope(b)):
                continue
            memo = domain.derived("lint.class_items", lambda d: {})
            why = _clash(a, b, items, rooms, memo) or _clash(b, a, items, rooms, memo)
            if why:
                w = where[("rule", persona.id, b.id)]
                out.append(Diagnostic(w.file, w.line, w.col, "L003",
                                      f"'{b.id}' and '{a.id}' cannot both be satisfied: {why}", "warning"))
    return out


def _clash(a: Preference, b: Preference, items: list, rooms: dict, memo: dict | None = None) -> str:
    for x in _atoms(a):
        for y in _atoms(b):
            if not (isinstance(x, A.Pred) and isinstance(y, A.Pred)):
                continue
            if x.op == "served_before" and y.op == "served_before" and x.subject == y.args[0] \
                    and y.subject == x.args[0]:
                return "opposite serving orders"
            if x.subject != y.subject:
                continue
            if x.op == "has" and y.op == "has_no":
                hit = _hits(x.args[0], items, rooms, memo)
                if hit and all(matches(y.args[0], i, rooms) for i in hit):
                    return f"one needs {_text(x.args[0])}, the other forbids {_text(y.args[0])}"
            if x.op == "adds_before" and y.op == "adds_before" and _same(x.args, tuple(reversed(y.args))):
                return "opposite orders"
    return ""


def _same(a: tuple, b: tuple) -> bool:
    return [_text(c) for c in a] == [_text(c) for c in b]


def _hits(cls, items: list, rooms: dict, memo: dict | None) -> list:
    """The catalogue items a class expression matches (kept in `memo` by the expression's text)."""
    key = _text(cls)
    hit = memo.get(key) if memo is not None else None
    if hit is None:
        hit = [i for i in items if matches(cls, i, rooms)]
        if memo is not None:
            memo[key] = hit
    return hit


def _forbidden(x, y, items: list, rooms: dict, memo: dict | None = None) -> str:
    """Why atom `x` (`S has X`) cannot hold together with atom `y` (`S has no Y` / `S has only Y`) on the
    same dishes, or ''. `memo` keeps the items each class matches."""
    if not (isinstance(x, A.Pred) and isinstance(y, A.Pred) and x.op == "has"):
        return ""
    hit = _hits(x.args[0], items, rooms, memo)
    if not hit:
        return ""
    if y.op == "has_no" and all(matches(y.args[0], i, rooms) for i in hit):
        return f"needs {_text(x.args[0])}, which the other forbids ({_text(y.args[0])})"
    if y.op == "has_only" and not any(matches(y.args[0], i, rooms) for i in hit):
        return f"needs {_text(x.args[0])}, but the other allows only {_text(y.args[0])}"
    return ""


def _cond_atoms(pref: Preference) -> list:
    cond = pref.rule.scope.cond if pref.rule.scope else None
    if cond is None:
        return []
    return list(cond.items) if isinstance(cond, A.AllOf) else [cond]


def _exclusive(a: Preference, b: Preference, items: list, rooms: dict, memo: dict) -> bool:
    """Whether the `if` conditions of a and b cannot hold together (`if it has milk` / `if it has no milk`),
    or one's condition already breaks the other (then keeping it false satisfies both)."""
    ca, cb = _cond_atoms(a), _cond_atoms(b)
    for x in ca:
        for y in cb:
            if isinstance(y, A.Not) and y.item == x or isinstance(x, A.Not) and x.item == y:
                return True
            if isinstance(x, A.Pred) and isinstance(y, A.Pred) and x.subject == y.subject and \
                    (_forbidden(x, y, items, rooms, memo) or _forbidden(y, x, items, rooms, memo)):
                return True
    for cond, other in ((ca, b), (cb, a)):
        if any(_forbidden(x, y, items, rooms, memo) or _forbidden(y, x, items, rooms, memo)
               for x in cond for y in _atoms(other) if isinstance(x, A.Pred) and isinstance(y, A.Pred)
               and x.subject == y.subject):
            return True
    return False


def _conditional_conflicts(domain: CompiledDomain, persona: Persona, where: dict, items: list, rooms: dict) -> list:
    """L005: pairs that clash whenever their `if` conditions hold (the plain pairs are L003)."""
    out = []
    prefs = list(persona.preferences)
    for i, a in enumerate(prefs):
        for b in prefs[i + 1:]:
            if not (_cond_atoms(a) or _cond_atoms(b)) or not _covers(domain, _scope(a), _scope(b)):
                continue
            memo = domain.derived("lint.class_items", lambda d: {})
            why = _clash(a, b, items, rooms, memo) or _clash(b, a, items, rooms, memo)
            if why and not _exclusive(a, b, items, rooms, domain.derived("lint.class_items", lambda d: {})):
                conds = " and ".join(f"'{p.rule.source.split(':', 1)[0].strip()}'" for p in (a, b) if _cond_atoms(p))
                w = where[("rule", persona.id, b.id)]
                out.append(Diagnostic(w.file, w.line, w.col, "L005",
                                      f"'{b.id}' and '{a.id}' cannot both be satisfied when {conds} hold(s): {why}",
                                      "warning"))
    return out


def _against_completion(domain: CompiledDomain, persona: Persona, where: dict, items: list, rooms: dict) -> list:
    """L004: a preference that no dish completing some component can satisfy (it forbids what the
    component's completion rule requires: no fruit, on a task with a fruit smoothie)."""
    out, memo = [], domain.derived("lint.class_items", lambda d: {})
    for pref in persona.preferences:
        w = where.get(("rule", persona.id, pref.id))
        limits = [y for y in _atoms(pref) if isinstance(y, A.Pred) and y.op in ("has_no", "has_only")]
        if not limits or w is None:
            continue
        for y in limits:
            for c in _subject_components(domain, pref, y.subject):
                why = next((r for x in _atoms_of(domain.component[c].completion) if isinstance(x, A.Pred)
                            and x.subject == "it" for r in [_forbidden(x, y, items, rooms, memo)] if r), "")
                if why:
                    when = " when its condition holds" if _cond_atoms(pref) else ""
                    out.append(Diagnostic(w.file, w.line, w.col, "L004",
                                          f"'{pref.id}' can never be satisfied on a task with {c}{when}: every {c} "
                                          f"{why.replace('the other', 'this preference')} (completion rule of {c})",
                                          "warning"))
    return out


def _atoms_of(rule: A.Rule) -> list:
    e = rule.expr
    return list(e.items) if isinstance(e, A.AllOf) else [e]


def _subject_components(domain: CompiledDomain, pref: Preference, subject: str) -> list:
    """The components whose dishes a subject word means, on the tasks the preference applies to."""
    in_tasks = {c for t in domain.tasks if applies_to(domain, pref, t) for c in t.components}
    if subject == "meal":
        return sorted(in_tasks)
    names = _scope(pref) if subject == "it" else (subject,)
    return sorted({c for n in names for c in domain.groups.get(n, (n,))} & in_tasks)
