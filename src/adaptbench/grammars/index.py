"""The per-domain grammar index: action forms as pieces with typed slots, the verb list with the
keyword/verb collisions resolved, and the `Look for` vocabulary. Built once per `CompiledDomain`
(`build_index`) and passed explicitly.

Ambiguity rule (documented in docs/grammar.md): `chop`, `heat`, `mix` and `serve` are action keywords
and freeform verbs. A freeform form `{verb} ...` and a dedicated form `Keyword ...` read the same string
only when the rest of both forms has the same shape (same literals, slots in the same places). Then the
dedicated action wins, as the runtime's try order has always decided: the verb is left out of that
freeform form, and the dedicated form's keyword also accepts the verb's lower-case spelling. Today only
`Chop {x} to get {y}` vs `{verb} {y} to get {z}` collides; `Heat {x}`, `Mix all items in ...` and
`Serve the object {x} at {y}` differ in shape from every freeform form, so `heat`, `mix` and `serve` stay
verbs everywhere.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the grammars read a domain's forms; they import nothing of the compiler
    from ..compiler.model import CompiledDomain


_STOP = {"a", "an", "the", "some", "of", "and", "or", "with", "for", "in", "on", "to"}


@dataclass(frozen=True)
class Lit:
    """A literal word of a form (spaces are separate pieces, never part of a literal)."""

    text: str
    alts: tuple = ()  # other accepted spellings (a keyword that is also a verb: its lower case)


@dataclass(frozen=True)
class Slot:
    """A typed slot: entity | content | thing | result | verb | query | question."""

    name: str
    kind: str


@dataclass(frozen=True)
class Form:
    """One surface form: literal words and slots, separated by single spaces."""

    pieces: tuple
    exclude_verbs: frozenset = frozenset()  # verbs this freeform form does not take (collisions)


@dataclass(frozen=True)
class ActionForms:
    """An action's forms; every form names its slots in the same order."""

    id: str
    forms: tuple
    slots: tuple  # slot names in form order

    @property
    def kinds(self) -> frozenset:
        """The slot kinds this action uses."""
        return frozenset(p.kind for f in self.forms for p in f.pieces if isinstance(p, Slot))


@dataclass(frozen=True)
class GrammarIndex:
    """Everything the grammar needs from a domain, derived once."""

    spec_hash: str
    actions: tuple  # ActionForms, spec order
    verbs: tuple  # sorted
    categories: tuple  # `Look for` phrases, sorted
    entities: tuple  # every entity id the domain declares, sorted
    substances: tuple  # every substance id, sorted
    layout: tuple  # rooms and furniture (what every episode starts knowing), sorted
    layout_contents: tuple  # contents of the layout, sorted
    collisions: tuple  # ((action id, verb), ...) resolved in favour of the dedicated action
    questions: tuple = ()  # the domain's questions (each choice's `ask`), sorted: the `bank` question set


def _pieces(form: str, types: dict) -> tuple:
    out = []
    for word in form.split(" "):
        m = re.fullmatch(r"\{(\w+)\}", word)
        out.append(Slot(m.group(1), types[m.group(1)]) if m else Lit(word))
    return tuple(out)


def _shape(pieces) -> tuple:
    return tuple(p.text if isinstance(p, Lit) else "<slot>" for p in pieces)


def _collisions(raw: list, verbs: set) -> list:
    """(dedicated action id, index of its form, freeform action id, freeform form index, verb)."""
    out = []
    for aid, forms in raw:
        for i, f in enumerate(forms):
            if not (isinstance(f[0], Lit) and f[0].text.lower() in verbs):
                continue
            for bid, bforms in raw:
                for j, g in enumerate(bforms):
                    if isinstance(g[0], Slot) and g[0].kind == "verb" and _shape(f[1:]) == _shape(g[1:]):
                        out.append((aid, i, bid, j, f[0].text.lower()))
    return out


def _actions(domain: CompiledDomain) -> tuple[tuple, tuple]:
    return action_forms(domain.actions, domain.verbs)


def action_forms(actions, verbs) -> tuple[tuple, tuple]:
    """(ActionForms per action, collisions) from action specs and the declared verbs: what `build_index`
    derives from a domain, also usable by the compiler before the domain exists. ValueError when an
    action's forms name their slots in different orders."""
    raw = [(a.id, [_pieces(f, dict(a.slots)) for f in a.forms]) for a in actions]
    hits = _collisions(raw, set(verbs))
    keyword_alts = {(aid, i): v for aid, i, _, _, v in hits}
    excluded: dict = {}
    for _, _, bid, j, v in hits:
        excluded.setdefault((bid, j), set()).add(v)
    actions = []
    for aid, forms in raw:
        built = []
        for i, pieces in enumerate(forms):
            if (aid, i) in keyword_alts:
                first = pieces[0]
                pieces = (Lit(first.text, (keyword_alts[aid, i],)), *pieces[1:])
            built.append(Form(pieces, frozenset(excluded.get((aid, i), ()))))
        orders = {tuple(p.name for p in f.pieces if isinstance(p, Slot)) for f in built}
        if len(orders) > 1:
            raise ValueError(f"action '{aid}': its forms name their slots in different orders {sorted(orders)}")
        actions.append(ActionForms(aid, tuple(built), next(iter(orders))))
    return tuple(actions), tuple(sorted((aid, v) for aid, _, _, _, v in hits))


_IRREGULAR = {"knife": "knives", "loaf": "loaves", "leaf": "leaves", "half": "halves", "shelf": "shelves",
              "potato": "potatoes", "tomato": "tomatoes", "mango": "mangoes", "person": "people",
              "mouse": "mice", "tooth": "teeth", "foot": "feet", "child": "children", "cheese": "cheeses"}
# mass nouns a person does not put in the plural ("look for milk", never "milks")
_MASS = frozenset(("milk", "water", "butter", "rice", "oatmeal", "muesli", "granola", "honey", "sugar", "salt",
                   "coffee", "tea", "yoghurt", "yogurt", "cream", "oil", "flour", "syrup", "juice", "jam", "bread",
                   "pepper", "cinnamon", "cardamom", "nutmeg", "ketchup", "mayonnaise", "mustard", "hummus",
                   "guacamole", "bacon", "toast", "food", "cutlery", "cookware", "dinnerware",
                   "drinkware", "equipment", "furniture", "spinach", "asparagus", "broccoli", "lettuce", "garlic",
                   "parsley", "basil", "cilantro", "oregano", "thyme", "rosemary", "dill", "chocolate", "sauce",
                   "yeast", "meat", "ham", "salmon", "tuna", "tofu", "quinoa"))


def plural(word: str) -> str:
    """The English plural of the last word of a phrase (eggs, berries, peaches, tomatoes, knives)."""
    head, _, last = word.rpartition(" ")
    if last in _IRREGULAR:
        out = _IRREGULAR[last]
    elif re.search(r"[^aeiou]y$", last):
        out = last[:-1] + "ies"
    elif re.search(r"(s|sh|ch|x|z)$", last):
        out = last + "es"
    else:
        out = last + "s"
    return f"{head} {out}" if head else out


def countable(word: str, nouns: frozenset) -> bool:
    """Whether a phrase ends in a countable noun in the singular (a thing of the catalogue a person counts),
    so its plural is a word a person would type: not an adjective (`wooden`), a plural (`eggs`), a mass noun."""
    last = word.rpartition(" ")[2]
    if last not in nouns or last in _MASS:
        return False
    return not (last.endswith("s") and not last.endswith(("ss", "us")))


# the catalogue's tags that describe (what a thing is like or made of) rather than name what it is
_DESCRIBING = frozenset(("aluminium", "caffeinated", "iron", "ceramic", "decaf", "dried", "durable", "edible", "fancy",
                         "flavored", "fresh", "frozen", "fat", "glass", "free", "herbal", "protein", "calorie",
                         "metal", "microwaveable", "movable", "stick", "based", "openable", "plain", "plastic",
                         "porcelain", "processed", "raw", "salted", "savory", "sharp", "silicone", "simple", "spicy",
                         "stainless", "sweet", "vegan", "grain", "wooden", "dairy", "liquid", "source", "storage",
                         "cleaning", "citrus", "sugar"))


def _nouns(domain: CompiledDomain) -> frozenset:
    """Nouns of the catalogue, last word of each: the categories of things and substances, the names of objects
    (pan_0 -> pan) and the tags that name a kind of thing (spice, vegetable, sweetener; not fresh, wooden)."""
    names = {e.category for e in domain.entities} | {s.category for s in domain.substances}
    names |= {re.sub(r"_\d+$", "", e.id) for e in domain.entities if e.kind == "movable"}
    tags = {t for x in (*domain.entities, *domain.substances) for t in x.tags}
    names |= {t for t in tags if t.rsplit("_", 1)[-1] not in _DESCRIBING}
    return frozenset(n.rsplit("_", 1)[-1] for n in names if n)


def _phrases_of(spec, domain) -> set:
    generic = set(domain.engine.search_ignores)
    keys = {spec.category} | (set(spec.tags) - generic)
    keys |= {t.rsplit("_", 1)[1] for t in spec.tags if "_" in t}
    keys.add(spec.id.rsplit("_", 1)[0] if re.search(r"_\d+$", spec.id) else spec.id)
    for name in getattr(spec, "contents", ()):
        keys.add(name)
        sub = domain.substance.get(name)
        if sub:
            keys |= {sub.category} | (set(sub.tags) - generic)
    return keys


def _categories(domain: CompiledDomain) -> tuple:
    """`Look for` phrases: categories, tags, substance and id names, description words and word
    pairs ('peanut butter'), those ending in a countable noun also in the plural, the last word only and the
    irregular ones right ('bread knives'; the runtime's search reads plurals)."""
    keys: set = set()
    for spec in (*domain.entities, *domain.substances):
        keys |= _phrases_of(spec, domain)
        words = re.findall(r"[a-z]+", spec.description.lower())
        keys |= {w for w in words if len(w) > 2 and w not in _STOP}
        keys |= {f"{a}_{b}" for a, b in zip(words, words[1:], strict=False) if not {a, b} & _STOP}
    phrases = {k.replace("_", " ") for k in keys if re.fullmatch(r"[a-z][a-z_]*[a-z]", k)}
    nouns = _nouns(domain)
    phrases |= {plural(p) for p in phrases if countable(p, nouns)}
    return tuple(sorted(phrases))


def build_index(domain: CompiledDomain) -> GrammarIndex:
    """Derive the grammar index of a domain (call once per domain and pass it around)."""
    actions, collisions = _actions(domain)
    layout = sorted(e.id for e in domain.entities if e.kind != "movable")
    contents = sorted({c for e in domain.entities if e.kind != "movable" for c in e.contents})
    return GrammarIndex(domain.spec_hash, actions, tuple(sorted(domain.verbs)), _categories(domain),
                        tuple(sorted(e.id for e in domain.entities)), tuple(sorted(domain.substance)),
                        tuple(layout), tuple(contents), collisions, domain_questions(domain))


def domain_questions(domain: CompiledDomain) -> tuple:
    """Every question the domain's choices ask (the planning choices' and each recipe's `ask`), sorted:
    the words the scripted askers use, and the questions a `bank` grammar allows."""
    choices = [*domain.planning, *(c for r in domain.recipes for c in r.choices)]
    return tuple(sorted({c.ask for c in choices if c.ask}))
