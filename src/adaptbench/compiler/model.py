"""The compiled domain: frozen dataclasses built from the spec, shared by every other part.

A `CompiledDomain` is immutable, carries a content hash of the spec it came from, and
round-trips through JSON (`to_json` / `from_json`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields
from functools import cached_property

from . import ast as A


@dataclass(frozen=True)
class Where:
    """A spec position: file and 1-based line/column."""

    file: str
    line: int
    col: int


@dataclass(frozen=True)
class EntitySpec:
    """A room, furniture item/appliance, or movable object of the master scene."""

    id: str
    kind: str  # room | furniture | movable
    description: str
    category: str
    tags: tuple
    location: str | None  # room for furniture, parent entity for movables, None for rooms
    contents: tuple = ()
    mandatory: bool = False


@dataclass(frozen=True)
class Substance:
    """Something held as contents (whole_milk, salt, water): a category and tags."""

    id: str
    description: str
    category: str
    tags: tuple


@dataclass(frozen=True)
class Precondition:
    """A rule the action's slots must satisfy, and the failure text (with {slot} fields)."""

    check: A.Rule
    fail: str


@dataclass(frozen=True)
class Effect:
    """One effect primitive and its parameters (values are templates over slots)."""

    primitive: str
    params: tuple  # ((name, value), ...)

    def param(self, name: str, default=None):
        """The value of parameter `name`, or `default`."""
        for k, v in self.params:
            if k == name:
                return v
        return default


@dataclass(frozen=True)
class ActionSpec:
    """An action template: surface forms, typed slots, preconditions, effects, success text."""

    id: str
    summary: str
    example: str
    forms: tuple
    slots: tuple  # ((name, type), ...)
    preconditions: tuple
    effects: tuple
    success: str


@dataclass(frozen=True)
class Component:
    """A dish a task asks for, its kind and groups, and the rule a served dish must satisfy."""

    id: str
    text: str
    kind: str
    groups: tuple
    completion: A.Rule
    requires: tuple = ()  # classes every scene keeps at least one of
    alt_kind: str | None = None  # the kind a dish has instead when `alt_when` holds for it (jam toast: sweet)
    alt_when: A.Rule | None = None


@dataclass(frozen=True)
class Style:
    """A named way a dish was made (scrambled, poached, iced ...)."""

    id: str
    text: str
    words: tuple
    verbs: tuple
    rule: A.Rule | None
    process: tuple = ()  # alternatives, each ((key, value), ...): see spec/tasks/styles.yaml


@dataclass(frozen=True)
class Option:
    """One option of a choice point, and what must be in the scene for it to be usable."""

    value: str
    needs: tuple = ()


@dataclass(frozen=True)
class Choice:
    """A choice point of a recipe (which milk, which cup, which toppings ...)."""

    id: str
    ask: str
    options: tuple
    default: tuple  # chosen values when nobody says otherwise
    multi: bool = False

    @property
    def values(self) -> tuple:
        """The option values."""
        return tuple(o.value for o in self.options)


@dataclass(frozen=True)
class Step:
    """A recipe step: an action template (`do`), a conditional block (`when`), or a loop (`for`)."""

    kind: str  # do | when | for
    text: str = ""
    cond: tuple = ()  # ((choice id, (values...)), ...); values may be ("any",) or ("none",)
    over: str = ""
    body: tuple = ()


@dataclass(frozen=True)
class Recipe:
    """How the scripted agents make one component (or an optional extra such as a side dish)."""

    id: str
    component: str | None
    optional: bool
    serve: str
    choices: tuple
    steps: tuple

    @property
    def choice(self) -> dict:
        """Choices by id."""
        return {c.id: c for c in self.choices}


@dataclass(frozen=True)
class Task:
    """A task: its text and the components it must complete."""

    id: str
    text: str
    components: tuple


@dataclass(frozen=True)
class Preference:
    """One persona preference: verbatim text, rule, topics (and an optional canned answer)."""

    id: str
    text: str
    rule: A.Rule
    topics: tuple
    answer: str = ""
    expected_lint: tuple = ()  # (code, why): linter warnings the spec acknowledges for this preference


@dataclass(frozen=True)
class Persona:
    """A persona and its preferences."""

    id: str
    name: str
    number: int
    description: str
    preferences: tuple


@dataclass(frozen=True)
class Engine:
    """What the simulator, verifiers, scripted agents and offline user rely on (spec/engine.yaml)."""

    dining_place: str  # the tag of the places dishes are served at
    food_kinds: tuple  # component kinds of solid food (the rule group `food`)
    drink_kinds: tuple  # component kinds of drinks (served first under `beverages_first`)
    states: tuple  # ((state, its opposite), ...) that `set_state` may set
    action_verbs: tuple  # verbs the dedicated actions record (mix, cook, chop)
    swap_families: tuple  # tags or categories the oracle swaps multi-choice items within
    location_words: tuple  # storage nouns that make a question one about where things are
    result_tags: tuple  # the tags of what a `to get` step makes (edible, food)
    search_ignores: tuple  # tags too general to find things by with `Look for` (container, edible ...)
    cold_places: tuple = ("fridge",)  # furniture categories that chill what is put in them
    water: str = "water"  # the category of water (a cooking medium for poached and boiled eggs)

    @property
    def kinds(self) -> tuple:
        """Every component kind."""
        return self.food_kinds + self.drink_kinds

    @property
    def state_names(self) -> tuple:
        """Every state, both sides of each pair."""
        return tuple(s for pair in self.states for s in pair)

    def opposite(self, state: str) -> str | None:
        """The opposite of a state, or None."""
        for a, b in self.states:
            if state in (a, b):
                return b if state == a else a
        return None


@dataclass(frozen=True)
class Split:
    """A cross-validation split: the personas it holds out (unseen); every other persona is seen."""

    id: int
    unseen: tuple


@dataclass(frozen=True, eq=False)
class CompiledDomain:
    """Everything the runtime, verifiers, grammars and prompts need, frozen."""

    spec_hash: str
    entities: tuple
    substances: tuple
    tags: tuple  # ((name, description), ...)
    categories: tuple
    verb_groups: tuple  # ((group, (verbs...)), ...)
    actions: tuple
    components: tuple
    styles: tuple
    tasks: tuple
    personas: tuple
    recipes: tuple = ()
    planning: tuple = ()
    processes: tuple = ()  # ((group, (verbs...)), ...): overlapping verb groups the styles test
    engine: Engine | None = None  # spec/engine.yaml (always set by the compiler)
    splits: tuple = ()  # Split, spec/splits.yaml

    @cached_property
    def unseen(self) -> dict:
        """Split id -> the persona ids it holds out."""
        return {s.id: s.unseen for s in self.splits}

    @cached_property
    def process(self) -> dict:
        """Verb group or process group -> its verbs (what `made by` and style processes test)."""
        out = {g: frozenset(vs) for g, vs in self.verb_groups}
        for g, vs in self.processes:
            out[g] = out.get(g, frozenset()) | frozenset(vs)
        return out

    @cached_property
    def entity(self) -> dict:
        """Entities by id."""
        return {e.id: e for e in self.entities}

    @cached_property
    def substance(self) -> dict:
        """Substances by id."""
        return {s.id: s for s in self.substances}

    @cached_property
    def action(self) -> dict:
        """Actions by id."""
        return {a.id: a for a in self.actions}

    @cached_property
    def component(self) -> dict:
        """Components by id."""
        return {c.id: c for c in self.components}

    @cached_property
    def style(self) -> dict:
        """Styles by id."""
        return {s.id: s for s in self.styles}

    @cached_property
    def task(self) -> dict:
        """Tasks by id."""
        return {t.id: t for t in self.tasks}

    @cached_property
    def recipe(self) -> dict:
        """Recipes by id."""
        return {r.id: r for r in self.recipes}

    @cached_property
    def persona(self) -> dict:
        """Personas by id."""
        return {p.id: p for p in self.personas}

    @cached_property
    def verbs(self) -> dict:
        """Verb -> group."""
        return {v: g for g, vs in self.verb_groups for v in vs}

    @cached_property
    def groups(self) -> dict:
        """Group name -> component ids (kinds, declared groups, `food`, `all`)."""
        out: dict[str, list] = {"all": [], "food": []}
        food = self.engine.food_kinds if self.engine else ()
        for c in self.components:
            out["all"].append(c.id)
            out.setdefault(c.kind, []).append(c.id)
            if c.alt_kind:
                out.setdefault(c.alt_kind, []).append(c.id)
            if c.kind in food:
                out["food"].append(c.id)
            for g in c.groups:
                out.setdefault(g, []).append(c.id)
        return {k: tuple(v) for k, v in out.items()}

    @cached_property
    def _derived(self) -> dict:
        return {}

    def derived(self, name: str, build):
        """A table derived from this domain by a later layer (grammar index, parser, search index,
        compiled rules ...): built once by `build(self)` and kept with the domain, so it lives exactly
        as long as the domain does (no module caches keyed by `id()`). Not serialised."""
        table = self._derived
        if name not in table:
            table[name] = build(self)
        return table[name]

    def counts(self) -> dict:
        """How many of each kind of thing the domain holds."""
        kinds = [e.kind for e in self.entities]
        return {"rooms": kinds.count("room"), "furniture": kinds.count("furniture"),
                "movables": kinds.count("movable"), "substances": len(self.substances),
                "actions": len(self.actions), "verbs": len(self.verbs), "tasks": len(self.tasks),
                "components": len(self.components), "personas": len(self.personas),
                "preferences": sum(len(p.preferences) for p in self.personas)}

    def to_json(self) -> str:
        """Serialise to JSON (the on-disk cache format)."""
        return json.dumps(_to_data(self), separators=(",", ":"))

    @staticmethod
    def from_json(text: str) -> CompiledDomain:
        """Rebuild a domain from `to_json` output."""
        return _from_data(json.loads(text))


_MODEL_TYPES = {c.__name__: c for c in (EntitySpec, Substance, Precondition, Effect, ActionSpec, Component,
                                        Style, Task, Preference, Persona, CompiledDomain, Option, Choice, Step,
                                        Recipe, Engine, Split)}


def _to_data(obj):
    if type(obj).__name__ in _MODEL_TYPES:
        out = {"_m": type(obj).__name__}
        for f in fields(obj):
            out[f.name] = _to_data(getattr(obj, f.name))
        return out
    if isinstance(obj, A.Node):
        return A.to_data(obj)
    if isinstance(obj, tuple | list):
        return [_to_data(x) for x in obj]
    return obj


def _from_data(data):
    if isinstance(data, dict):
        if "_m" in data:
            cls = _MODEL_TYPES[data["_m"]]
            return cls(**{k: _from_data(v) for k, v in data.items() if k != "_m"})
        if "_t" in data:
            return A.from_data(data)
        return {k: _from_data(v) for k, v in data.items()}
    if isinstance(data, list):
        return tuple(_from_data(x) for x in data)
    return data
