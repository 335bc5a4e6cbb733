"""Build the frozen model from validated documents, parsing every rule with file positions."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from . import ast as A
from .diagnostics import Diagnostic
from .model import (
    ActionSpec,
    Choice,
    Component,
    Effect,
    Engine,
    EntitySpec,
    Option,
    Persona,
    Precondition,
    Preference,
    Recipe,
    Split,
    Step,
    Style,
    Substance,
    Task,
    Where,
)
from .rules import RuleSyntaxError, parse_rule
from .yamlpos import LoadedDoc


@dataclass
class Draft:
    """Everything read from the spec before semantic checks; `where` maps keys to positions."""

    entities: list = field(default_factory=list)
    substances: list = field(default_factory=list)
    tags: dict = field(default_factory=dict)
    categories: dict = field(default_factory=dict)
    verb_groups: dict = field(default_factory=dict)
    processes: dict = field(default_factory=dict)
    actions: list = field(default_factory=list)
    components: list = field(default_factory=list)
    styles: list = field(default_factory=list)
    tasks: list = field(default_factory=list)
    personas: list = field(default_factory=list)
    recipes: list = field(default_factory=list)
    planning: list = field(default_factory=list)
    engine: Engine | None = None
    splits: list = field(default_factory=list)
    broken: set = field(default_factory=set)  # ids of persona files that did not load (already reported)
    where: dict = field(default_factory=dict)  # (kind, id[, field]) -> Where
    diags: list = field(default_factory=list)

    def at(self, doc: LoadedDoc, path: tuple, key: bool = False) -> Where:
        """The Where of `path` in `doc`."""
        m = doc.pos.key(path) if key else doc.pos.at(path)
        return Where(doc.file, m.line, m.col)

    def claim(self, kind: str, ident: str, where: Where) -> None:
        """Register the definition of `ident` in namespace `kind`; a second definition is D001."""
        first = self.where.get((kind, ident))
        if first is not None:
            self.error(where, "D001", f"duplicate {kind} id '{ident}' (first defined at {first.file}:{first.line})")
            return
        self.where[(kind, ident)] = where

    def error(self, where: Where, code: str, message: str, severity: str = "error") -> None:
        """Record a diagnostic."""
        self.diags.append(Diagnostic(where.file, where.line, where.col, code, message, severity))


def rule_at(draft: Draft, doc: LoadedDoc, path: tuple, text: str) -> A.Rule | None:
    """Parse rule `text` found at `path`, shifting positions into the file; None on syntax error."""
    mark = doc.pos.at(path)
    quoted = mark.style in ('"', "'")
    block = mark.style in ("|", ">")
    line_off = mark.line if block else mark.line - 1
    col_off = (mark.col + 1 if block else mark.col - 1 + int(quoted))
    try:
        rule = parse_rule(text)
    except RuleSyntaxError as exc:
        col = exc.col + (col_off if exc.line == 1 else 0)
        what = "rule syntax error: " if exc.code == "R001" else ""
        draft.error(Where(doc.file, exc.line + line_off, col), exc.code, f"{what}{exc.message}")
        return None
    return replace(A.shift(rule, line_off, col_off), file=doc.file)


def add_objects(draft: Draft, doc: LoadedDoc) -> None:
    """Read rooms, furniture, objects, substances, tags and categories from one objects file."""
    data = doc.data
    for i, r in enumerate(data.get("rooms", [])):
        draft.entities.append(EntitySpec(r["id"], "room", r["description"], "room", ("room",), None))
        draft.claim("entity", r["id"], draft.at(doc, ("rooms", i, "id")))
    for i, f in enumerate(data.get("furniture", [])):
        tags = tuple(f.get("tags", ())) + ("furniture",)
        draft.entities.append(EntitySpec(f["id"], "furniture", f["description"], f["category"], tags, f["room"],
                                         tuple(f.get("contents", ())), True))
        _remember(draft, doc, "entity", f["id"], ("furniture", i), ("category", "tags", "room", "contents"))
    for i, o in enumerate(data.get("objects", [])):
        tags = tuple(o.get("tags", ())) + ("movable",)
        draft.entities.append(EntitySpec(o["id"], "movable", o["description"], o["category"], tags, o["location"],
                                         tuple(o.get("contents", ())), bool(o.get("mandatory", False))))
        _remember(draft, doc, "entity", o["id"], ("objects", i), ("category", "tags", "location", "contents"))
    for i, s in enumerate(data.get("substances", [])):
        draft.substances.append(Substance(s["id"], s["description"], s["category"], tuple(s.get("tags", ()))))
        _remember(draft, doc, "substance", s["id"], ("substances", i), ("category", "tags"))
    for key in ("tags", "categories"):
        for name, text in data.get(key, {}).items():
            getattr(draft, key)[name] = text
            draft.where[(key, name)] = draft.at(doc, (key, name), key=True)


def _remember(draft: Draft, doc: LoadedDoc, kind: str, ident: str, path: tuple, fields_: tuple) -> None:
    draft.claim(kind, ident, draft.at(doc, path + ("id",)))
    for f in fields_:
        draft.where[(kind, ident, f)] = draft.at(doc, path + (f,))
        items = doc.data
        for p in path + (f,):
            items = items.get(p) if isinstance(items, dict) else items[p] if isinstance(items, list) else None
            if items is None:
                break
        if isinstance(items, list):
            for j in range(len(items)):
                draft.where[(kind, ident, f, j)] = draft.at(doc, path + (f, j))


def _effects(draft: Draft, doc: LoadedDoc, path: tuple, a: dict) -> list:
    effects = []
    for j, e in enumerate(a["effects"]):
        (prim, params), = e.items()
        effects.append(Effect(prim, tuple((k, str(v)) for k, v in (params or {}).items())))
        draft.where[("effect", a["id"], j)] = draft.at(doc, path + ("effects", j))
        for k in params or {}:
            draft.where[("effect", a["id"], j, k)] = draft.at(doc, path + ("effects", j, prim, k))
    return effects


def add_actions(draft: Draft, doc: LoadedDoc) -> None:
    """Read action templates and verb groups from one actions file."""
    for i, a in enumerate(doc.data.get("actions", [])):
        path = ("actions", i)
        pres = []
        for j, p in enumerate(a.get("preconditions", [])):
            rule = rule_at(draft, doc, path + ("preconditions", j, "check"), p["check"])
            if rule is not None:
                pres.append(Precondition(rule, p["fail"]))
        effects = _effects(draft, doc, path, a)
        slots = tuple(a.get("slots", {}).items())
        draft.actions.append(ActionSpec(a["id"], a["summary"], a.get("example", ""), tuple(a["forms"]), slots,
                                        tuple(pres), tuple(effects), a["success"]))
        draft.claim("action", a["id"], draft.at(doc, path + ("id",)))
        for name, _ in slots:
            draft.where[("slot", a["id"], name)] = draft.at(doc, path + ("slots", name))
        for j in range(len(a["forms"])):
            draft.where[("form", a["id"], j)] = draft.at(doc, path + ("forms", j))
    for group, verbs in doc.data.get("verbs", {}).items():
        draft.verb_groups.setdefault(group, []).extend(verbs)
        for j, v in enumerate(verbs):
            draft.where.setdefault(("verb", v), draft.at(doc, ("verbs", group, j)))
    for group, verbs in doc.data.get("processes", {}).items():
        draft.processes.setdefault(group, []).extend(verbs)
        draft.where.setdefault(("process", group), draft.at(doc, ("processes", group)))


def add_tasks(draft: Draft, doc: LoadedDoc) -> None:
    """Read tasks, components and styles from one tasks file."""
    data = doc.data
    for i, t in enumerate(data.get("tasks", [])):
        draft.tasks.append(Task(t["id"], t["text"], tuple(t["components"])))
        draft.claim("task", t["id"], draft.at(doc, ("tasks", i, "id")))
        for j in range(len(t["components"])):
            draft.where[("task", t["id"], "components", j)] = draft.at(doc, ("tasks", i, "components", j))
    for i, c in enumerate(data.get("components", [])):
        rule = rule_at(draft, doc, ("components", i, "completion"), c["completion"])
        alt = c.get("kind_if")
        when = rule_at(draft, doc, ("components", i, "kind_if", "when"), alt["when"]) if alt else None
        if rule is not None:
            draft.components.append(Component(c["id"], c["text"], c["kind"], tuple(c.get("groups", ())), rule,
                                              tuple(c.get("requires", ())), alt["kind"] if alt else None, when))
        draft.claim("component", c["id"], draft.at(doc, ("components", i, "id")))
    for i, s in enumerate(data.get("styles", [])):
        rule = rule_at(draft, doc, ("styles", i, "rule"), s["rule"]) if "rule" in s else None
        process = tuple(tuple(sorted(alt.items())) for alt in s.get("process", ()))
        draft.styles.append(Style(s["id"], s["text"], tuple(s.get("words", ())), tuple(s.get("verbs", ())), rule,
                                  process))
        draft.claim("style", s["id"], draft.at(doc, ("styles", i, "id")))
    add_recipes(draft, doc)


def _choice(data: dict) -> Choice:
    options = tuple(Option(o) if isinstance(o, str) else Option(o["value"], tuple(o.get("needs", ())))
                    for o in data["options"])
    multi = bool(data.get("multi", False))
    default = data.get("default", [] if multi else options[0].value)
    default = tuple(default) if isinstance(default, list) else (default,)
    return Choice(data["id"], data.get("ask", ""), options, default, multi)


def _step(data) -> Step:
    if isinstance(data, str):
        return Step("do", text=data)
    body = tuple(_step(s) for s in data["do"])
    if "for" in data:
        return Step("for", over=data["for"], body=body)
    cond = tuple((k, tuple(v) if isinstance(v, list) else (v,)) for k, v in data["when"].items())
    return Step("when", cond=cond, body=body)


def add_recipes(draft: Draft, doc: LoadedDoc) -> None:
    """Read recipes and planning choices from a tasks file."""
    for i, c in enumerate(doc.data.get("planning", [])):
        draft.planning.append(_choice(c))
        draft.where[("planning", c["id"])] = draft.at(doc, ("planning", i, "id"))
    for i, r in enumerate(doc.data.get("recipes", [])):
        choices = tuple(_choice(c) for c in r["choices"])
        draft.recipes.append(Recipe(r["id"], r.get("component"), bool(r.get("optional", False)), r["serve"],
                                    choices, tuple(_step(s) for s in r["steps"])))
        draft.claim("recipe", r["id"], draft.at(doc, ("recipes", i, "id")))
        for j, c in enumerate(r["choices"]):
            draft.where[("choice", r["id"], c["id"])] = draft.at(doc, ("recipes", i, "choices", j, "id"))
            for k in range(len(c["options"])):
                draft.where[("option", r["id"], c["id"], k)] = draft.at(doc, ("recipes", i, "choices", j, "options", k))
        marks: list = []
        _step_marks(doc, ("recipes", i, "steps"), r["steps"], marks)
        draft.where[("steps", r["id"])] = marks


def _step_marks(doc: LoadedDoc, path: tuple, steps: list, out: list) -> None:
    """The position (file, line, col, scalar style) of every step, in the order `Step`s are walked: a
    step, then the body of a `when`/`for` (the `when`/`for` key's position stands for the block)."""
    for j, s in enumerate(steps):
        if isinstance(s, str):
            m = doc.pos.at(path + (j,))
            out.append((doc.file, m.line, m.col, m.style))
            continue
        key = "for" if "for" in s else "when"
        m = doc.pos.at(path + (j, key))
        out.append((doc.file, m.line, m.col, m.style))
        _step_marks(doc, path + (j, "do"), s["do"], out)


def add_persona(draft: Draft, doc: LoadedDoc) -> None:
    """Read one persona file."""
    data = doc.data
    prefs = []
    for i, p in enumerate(data["preferences"]):
        rule = rule_at(draft, doc, ("preferences", i, "rule"), p["rule"])
        if rule is not None:
            prefs.append(Preference(p["id"], p["text"], rule, tuple(p["topics"]), p.get("answer", ""),
                                    tuple(sorted(p.get("expected_lint", {}).items()))))
        draft.claim(f"preference of {data['id']}", p["id"], draft.at(doc, ("preferences", i, "id")))
        draft.where[("rule", data["id"], p["id"])] = draft.at(doc, ("preferences", i, "rule"))
    draft.personas.append(Persona(data["id"], data["name"], int(data.get("number", 0)),
                                  data.get("description", ""), tuple(prefs)))
    draft.claim("persona", data["id"], draft.at(doc, ("id",)))
    draft.where[("persona_file", data["id"])] = doc.file
    if "number" in data:
        draft.where[("persona", data["id"], "number")] = draft.at(doc, ("number",))


def add_engine(draft: Draft, doc: LoadedDoc) -> None:
    """Read spec/engine.yaml: the words the engine relies on."""
    d = doc.data
    draft.claim("engine vocabulary", "engine", draft.at(doc, ()))
    draft.engine = Engine(d["dining_place"], tuple(d["kinds"]["food"]), tuple(d["kinds"]["drink"]),
                          tuple(tuple(p) for p in d["states"]), tuple(d["action_verbs"]),
                          tuple(d["swap_families"]), tuple(d["location_words"]), tuple(d["result_tags"]),
                          tuple(d["search_ignores"]), tuple(d["cold_places"]), d["water"])
    for key in ("dining_place", "states", "action_verbs", "swap_families", "location_words", "result_tags",
                "search_ignores", "cold_places", "water"):
        draft.where[("engine", key)] = draft.at(doc, (key,))
        for j in range(len(d[key]) if isinstance(d[key], list) else 0):
            draft.where[("engine", key, j)] = draft.at(doc, (key, j))
    for group in ("food", "drink"):
        for j in range(len(d["kinds"][group])):
            draft.where[("engine", "kinds", group, j)] = draft.at(doc, ("kinds", group, j))


def add_splits(draft: Draft, doc: LoadedDoc) -> None:
    """Read spec/splits.yaml: the cross-validation splits."""
    for i, sp in enumerate(doc.data["splits"]):
        draft.splits.append(Split(int(sp["id"]), tuple(sp["unseen"])))
        draft.claim("split", str(sp["id"]), draft.at(doc, ("splits", i, "id")))
        for j in range(len(sp["unseen"])):
            draft.where[("split", int(sp["id"]), j)] = draft.at(doc, ("splits", i, "unseen", j))
    draft.where[("splits",)] = draft.at(doc, ("splits",), key=True)


ADDERS = {"objects": add_objects, "actions": add_actions, "tasks": add_tasks, "persona": add_persona,
          "engine": add_engine, "splits": add_splits}
