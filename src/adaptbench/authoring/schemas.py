"""JSON Schemas for editors: the package's schemas plus field descriptions and, when a spec is given, the
names it declares (tags, categories, locations, substances, components, styles) for completion."""

from __future__ import annotations

import copy

DOCS = {  # (kind, dotted path under properties/items) -> description
    ("objects", "objects.category"): "what the object IS: one category (spec/objects/vocabulary.yaml)",
    ("objects", "objects.tags"): "what the object is LIKE: tags rules can talk about (vocabulary.yaml)",
    ("objects", "objects.location"): "a furniture item, or another object that holds it (a container)",
    ("objects", "objects.contents"): "substances it holds (spec/objects/substances.yaml)",
    ("objects", "objects.mandatory"): "always in the scene (otherwise present with probability 0.7)",
    ("objects", "furniture.room"): "the room it stands in",
    ("objects", "substances.category"): "what the substance IS: one category",
    ("objects", "substances.tags"): "what the substance is LIKE: tags rules can talk about",
    ("tasks", "tasks.components"): "the components (dishes) the task asks for",
    ("tasks", "components.kind"): "sweet | savory | beverage: persona rules target kinds",
    ("tasks", "components.groups"): "extra groups persona rules can target (egg_dish, bread_dish, ...)",
    ("tasks", "components.completion"): "rule on `it` (one served dish) that completes the component (docs/rules.md)",
    ("tasks", "components.requires"): "classes every sampled scene keeps at least one of",
    ("persona", "id"): "the persona id: must equal the file name",
    ("persona", "number"): "the persona's number, unique across personas",
    ("persona", "preferences.rule"): "what the verifier checks (docs/rules.md); names: `adapt vocab`",
    ("persona", "preferences.text"): "what the persona would say",
    ("persona", "preferences.topics"): "words a question about this preference would use",
    ("persona", "preferences.answer"): "what the offline user answers when asked about it",
}


def _node(schema: dict, dotted: str) -> dict | None:
    node = schema
    for part in dotted.split("."):
        node = node.get("properties", {}).get(part)
        if node is None:
            return None
        node = node.get("items", node) if node.get("type") == "array" and part != dotted.split(".")[-1] else node
    return node


def _names(pairs) -> dict:
    return {"anyOf": [{"const": n, "description": d} for n, d in pairs]} if pairs else {}


def _declared(domain) -> dict:
    """(kind, dotted path) -> a schema listing the declared names allowed there."""
    tags = list(domain.tags)
    cats = list(domain.categories)
    holders = [(e.id, e.description) for e in domain.entities if e.kind != "room"]
    rooms = [(e.id, e.description) for e in domain.entities if e.kind == "room"]
    subs = [(s.id, s.description) for s in domain.substances]
    comps = [(c.id, c.text) for c in domain.components]
    groups = sorted({g for c in domain.components for g in c.groups})
    return {
        ("objects", "objects.category"): _names(cats), ("objects", "substances.category"): _names(cats),
        ("objects", "furniture.category"): _names(cats),
        ("objects", "objects.tags"): _names(tags), ("objects", "substances.tags"): _names(tags),
        ("objects", "furniture.tags"): _names(tags),
        ("objects", "objects.location"): _names(holders),
        ("objects", "furniture.room"): _names(rooms),
        ("objects", "objects.contents"): _names(subs), ("objects", "furniture.contents"): _names(subs),
        ("tasks", "tasks.components"): _names(comps),
        ("tasks", "components.groups"): _names([(g, "a component group") for g in groups]),
        ("tasks", "components.requires"): _names(tags + cats),
        ("splits", "splits.unseen"): _names([(p.id, f"persona {p.number}: {p.name}") for p in domain.personas]),
    }


def schemas(domain=None) -> dict:
    """{file name: schema} for every kind of spec file; with `domain`, lists of ids and names carry the
    declared names (an editor completes them and flags undeclared ones)."""
    from ..compiler.loader import SCHEMA_KINDS, schema

    out = {}
    declared = _declared(domain) if domain is not None else {}
    for kind in SCHEMA_KINDS:
        data = copy.deepcopy(schema(kind))
        for (k, dotted), text in DOCS.items():
            node = _node(data, dotted) if k == kind else None
            if node is not None:
                node.setdefault("description", text)
        for (k, dotted), names in declared.items():
            node = _node(data, dotted) if k == kind else None
            if node is not None and names:
                target = node["items"] if node.get("type") == "array" else node
                target.update(names)
        out[f"{kind}.schema.json"] = data
    return out
