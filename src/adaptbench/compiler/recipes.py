"""Recipe steps checked like every other part of the spec (docs/recipes.md).

Every step is read, with its placeholders filled, by the structural grammar the simulator parses
actions with (`grammars.match`, the same forms and terminals): a step that no action form accepts is
an error with the closest form; a verb, an entity or a content named in a step must be declared; the
options a step puts into a slot must be things of the catalogue that slot can take; `when` values
must be options of their choice and `for` must loop over a multi choice. A task component that no
recipe makes is a warning. Codes D404-D410 (docs/errors.md).
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field

from .build import Draft
from .diagnostics import did_you_mean
from .model import Where

_VAR = re.compile(r"\{(src:)?(\w+)\}")
_ADD = re.compile(r"^ADD (\S+) TO (\S+)$")
_ID = re.compile(r"[a-z_]*\d|\w*_\w*")  # a word that reads as an id (pan_0, whole_milk), not as a form word
_ROLE = {"entity": "an entity (a movable, furniture or appliance id)",
         "thing": "an entity or a substance", "add": "an entity, a substance or a category"}


@dataclass
class _Catalogue:
    entities: set
    substances: set
    categories: set
    verbs: dict  # lower-case verb or keyword -> its spelling (did-you-mean candidates)
    declared: set  # the verbs a verb slot takes


@dataclass
class _Recipe:
    """What one recipe's check accumulates."""

    id: str
    choices: dict
    marks: list
    results: set = field(default_factory=set)
    patterns: list = field(default_factory=list)
    uses: dict = field(default_factory=dict)  # choice id -> {role: (where, step text)}
    when: dict = field(default_factory=dict)  # (where, choice) -> [its options, values tested]: shared by recipes
    pos: int = 0

    def next_mark(self, draft_file: str) -> tuple:
        """The next step's (file, line, col, style)."""
        m = self.marks[self.pos] if self.pos < len(self.marks) else (draft_file, 1, 1, None)
        self.pos += 1
        return m


def check_recipe_steps(draft: Draft) -> None:
    """Parse and check every recipe step; warn about task components no recipe makes."""
    from ..grammars.index import action_forms  # the grammars import the compiler's model
    from ..grammars.match import FormMatcher, slot_kinds

    verbs = {v for vs in draft.verb_groups.values() for v in vs}
    try:
        actions, _ = action_forms(draft.actions, verbs)
        matcher, kinds = FormMatcher(actions), slot_kinds(actions)
    except (ValueError, KeyError):  # bad forms or slot types, already reported (D201, D202): steps cannot
        return                      # be read against them
    cat = _Catalogue({e.id for e in draft.entities}, {s.id for s in draft.substances}, set(draft.categories),
                     {**{k.lower(): k for k in matcher.keywords()}, **{v: v for v in verbs}}, verbs)
    seen: set = set()
    when: dict = {}
    for r in draft.recipes:
        rec = _Recipe(r.id, {c.id: c for c in draft.planning} | {c.id: c for c in r.choices},
                      draft.where.get(("steps", r.id), []), when=when)
        _collect_results(r.steps, matcher, kinds, rec)
        _walk(draft, r.steps, {}, rec, matcher, kinds, cat, seen)
        for name in (r.serve, "place"):  # served at the end: `Move {serve} to {place}`
            rec.uses.setdefault(name, {}).setdefault("entity", (None, f"Move {{{r.serve}}} to {{place}}"))
        _check_options(draft, rec, cat, seen)
    _report_when(draft, when, seen)
    _missing_recipes(draft)


# ---------------------------------------------------------------- walking the steps
def _walk(draft, steps, loop: dict, rec: _Recipe, matcher, kinds, cat, seen) -> None:
    for s in steps:
        mark = rec.next_mark("<spec>")
        if s.kind == "do":
            _check_do(draft, s.text, mark, loop, rec, matcher, kinds, cat, seen)
        elif s.kind == "for":
            inner = _check_for(draft, s.over, mark, rec, seen)
            _walk(draft, s.body, {**loop, "item": inner} if inner else loop, rec, matcher, kinds, cat, seen)
        else:
            _check_when(draft, s.cond, mark, rec, seen)
            _walk(draft, s.body, loop, rec, matcher, kinds, cat, seen)


def _error(draft: Draft, seen: set, where: Where, code: str, message: str, severity: str = "error") -> None:
    key = (where, code, message)
    if key not in seen:  # recipes sharing steps through a YAML anchor report them once
        seen.add(key)
        draft.error(where, code, message, severity)


def _at(mark: tuple, text: str = "", fragment: str = "") -> Where:
    """The position of `fragment` inside the step `text` at `mark` (the step's start when unknown)."""
    file, line, col, style = mark
    i = text.find(fragment) if fragment else -1
    if i < 0 or style not in (None, "", '"', "'") or "\n" in text:
        return Where(file, line, col)
    return Where(file, line, col + i + bool(style))


def _check_for(draft, over: str, mark, rec: _Recipe, seen) -> str | None:
    where = Where(*mark[:3])
    c = rec.choices.get(over)
    if c is None:
        _error(draft, seen, where, "D404", f"recipe '{rec.id}': 'for: {over}' is not a choice"
                                           f"{did_you_mean(over, rec.choices)}")
        return None
    if not c.multi:
        _error(draft, seen, where, "D409", f"recipe '{rec.id}': 'for: {over}' loops over a single choice; "
                                           f"`for` needs a multi choice (multi: true)")
    return over


def _check_when(draft, cond, mark, rec: _Recipe, seen) -> None:
    """Unknown choices now; values later (`_report_when`): steps shared through a YAML anchor (eggs and
    omelette) may test a value that only some of the recipes sharing them offer."""
    where = Where(*mark[:3])
    for name, values in cond:
        c = rec.choices.get(name)
        if c is None:
            _error(draft, seen, where, "D404", f"recipe '{rec.id}': 'when: {name}' is not a choice"
                                               f"{did_you_mean(name, rec.choices)}")
            continue
        entry = rec.when.setdefault((where, name), [set(), set()])
        entry[0].update(c.values)
        entry[1].update(values)


def _report_when(draft: Draft, when: dict, seen: set) -> None:
    for (where, name), (options, values) in when.items():
        allowed = options | {"any", "none"}
        for v in sorted(values - allowed):
            _error(draft, seen, where, "D409", f"'when: {name}: {v}': '{v}' is not an option of '{name}'"
                                               f"{did_you_mean(v, allowed)} (options: {', '.join(sorted(options))}; "
                                               f"or any / none)")


# ---------------------------------------------------------------- one step
def _fill(text: str) -> tuple[str, dict]:
    """The step with each placeholder replaced by a token the grammar reads as a name; token -> (src, name)."""
    tokens: dict = {}

    def token(m) -> str:
        t = f"ph{len(tokens)}q"
        tokens[t] = (bool(m.group(1)), m.group(2))
        return t
    return _VAR.sub(token, text), tokens


def _check_do(draft, text: str, mark, loop: dict, rec: _Recipe, matcher, kinds, cat, seen) -> None:
    ok = True
    for m in _VAR.finditer(text):
        if m.group(2) not in loop and m.group(2) not in rec.choices:
            ok = False
            _error(draft, seen, _at(mark, text, m.group(0)), "D404",
                   f"recipe '{rec.id}': step '{text}' uses unknown choice '{m.group(2)}'"
                   f"{did_you_mean(m.group(2), set(rec.choices) | set(loop))}")
    if not ok:
        return
    if text.startswith("ADD ") or text == "ADD":
        _check_add(draft, text, mark, loop, rec, cat, seen)
        return
    filled, tokens = _fill(text)
    parsed = matcher.match(filled)
    if parsed is None:
        _error(draft, seen, _at(mark), "D405", f"step '{text}' does not read as any action"
                                               f"{_closest(filled, tokens, matcher, cat)}")
        return
    for slot, value in parsed.slots:
        _check_slot(draft, text, mark, kinds[parsed.action][slot], value, tokens, loop, rec, cat, seen)


def _check_add(draft, text: str, mark, loop, rec: _Recipe, cat, seen) -> None:
    m = _ADD.match(text)
    if m is None:
        _error(draft, seen, _at(mark), "D405", f"step '{text}': an ADD step reads "
                                               f"'ADD <what> TO <vessel>' (one word each, e.g. 'ADD {{milk}} TO {{cup}}')")
        return
    filled, tokens = _fill(text)
    what, vessel = _ADD.match(filled).groups()
    _check_slot(draft, text, mark, "add", what, tokens, loop, rec, cat, seen)
    _check_slot(draft, text, mark, "entity", vessel, tokens, loop, rec, cat, seen)


def _check_slot(draft, text, mark, kind: str, value: str, tokens: dict, loop, rec: _Recipe, cat, seen) -> None:
    if value in tokens:
        src, name = tokens[value]
        choice = loop.get(name, name)
        role = "thing" if src else _role(kind)
        if role in _ROLE:
            rec.uses.setdefault(choice, {}).setdefault(role, (_at(mark, text, "{"), text))
        return
    if any(t in value for t in tokens):
        return  # built from a placeholder (chopped_{item}): a result name
    if kind == "verb":
        if value.lower() not in cat.declared:
            _unknown_verb(draft, text, mark, value, rec, cat, seen)
        return
    pool = _pool(kind, cat, rec)
    if pool is not None and value not in pool and not any(p.fullmatch(value) for p in rec.patterns):
        _error(draft, seen, _at(mark, text, value), "D407",
               f"step '{text}': '{value}' is not {_ROLE[_role(kind)]}"
               f"{' or a result of an earlier step' if kind != 'entity' else ''}{did_you_mean(value, pool)}")


def _role(kind: str) -> str:
    return "thing" if kind == "content" else kind


def _pool(kind: str, cat: _Catalogue, rec: _Recipe) -> set | None:
    if kind == "entity":
        return cat.entities
    if kind in ("thing", "content"):
        return cat.entities | cat.substances | rec.results
    if kind == "add":
        return cat.entities | cat.substances | cat.categories | rec.results
    return None


def _unknown_verb(draft, text, mark, verb: str, rec: _Recipe, cat: _Catalogue, seen) -> None:
    close = difflib.get_close_matches(verb.lower(), list(cat.verbs), n=1, cutoff=0.6)
    hint = f" (did you mean '{cat.verbs[close[0]]}'?)" if close else ""
    _error(draft, seen, _at(mark, text, verb), "D406",
           f"step '{text}': '{verb}' is not a declared verb or action keyword{hint}")


def _closest(filled: str, tokens: dict, matcher, cat: _Catalogue) -> str:
    """' (closest form: `Move {x} from {y} to {z}`)' by the words of the step, ids and slots as wildcards."""
    def generic(words: list) -> str:
        return " ".join("_" if (w in tokens or _ID.fullmatch(w) or w in cat.entities or w in cat.substances
                                or w.startswith("{")) else w for w in words)
    shapes = {generic(shape.split(" ")): shape for _, shape in matcher.shapes()}
    close = difflib.get_close_matches(generic(filled.split(" ")), list(shapes), n=1, cutoff=0.5)
    return f" (closest form: '{shapes[close[0]]}')" if close else ""


# ---------------------------------------------------------------- results, options, components
def _collect_results(steps, matcher, kinds: dict, rec: _Recipe) -> None:
    """Names the recipe's steps make (`... to get scrambled_eggs`, `chopped_{item}`): contents later steps may use."""
    for s in steps:
        if s.kind != "do":
            _collect_results(s.body, matcher, kinds, rec)
            continue
        filled, tokens = _fill(s.text)
        parsed = matcher.match(filled)
        for slot, value in parsed.slots if parsed else ():
            if kinds[parsed.action][slot] != "result":
                continue
            if any(t in value for t in tokens):
                pattern = re.escape(value)
                for t in tokens:
                    pattern = pattern.replace(t, r"[a-z0-9_]+")
                rec.patterns.append(re.compile(pattern))
            else:
                rec.results.add(value)


def _check_options(draft: Draft, rec: _Recipe, cat: _Catalogue, seen) -> None:
    """Options a step puts into a slot are catalogue things that slot takes (`none` means skip it)."""
    for cid, roles in rec.uses.items():
        c = rec.choices.get(cid)
        if c is None:
            continue
        for role, (_where, text) in roles.items():
            pool = _pool(role, cat, rec)
            for k, o in enumerate(c.options):
                if o.value == "none" or o.value in pool:
                    continue
                where = draft.where.get(("option", rec.id, cid, k)) or draft.where.get(("planning", cid)) \
                    or Where("<spec>", 1, 1)
                _error(draft, seen, where, "D408",
                       f"option '{o.value}' of choice '{cid}' is not {_ROLE[role]}{did_you_mean(o.value, pool)}, "
                       f"but step '{text}' puts it there")


def _missing_recipes(draft: Draft) -> None:
    made = {r.component for r in draft.recipes if r.component and not r.optional}
    for t in draft.tasks:
        for j, c in enumerate(t.components):
            if c not in made and ("task", t.id, "components", j) in draft.where:
                draft.error(draft.where[("task", t.id, "components", j)], "D410",
                            f"no recipe makes component '{c}' of task '{t.id}': the scripted agents (oracle, "
                            f"never-ask, always-ask) cannot make it (add a recipe to spec/tasks/recipes.yaml)",
                            "warning")
