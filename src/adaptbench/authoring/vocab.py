"""The names rules may use (`adapt vocab`): tags, categories, components and groups, styles — each with
what it matches."""

from __future__ import annotations


def _items(domain) -> list:
    return [*domain.entities, *domain.substances]


def _matches(items: list, name: str) -> list:
    return [x.id for x in items if x.category == name or name in x.tags]


def _few(ids: list, n: int = 4) -> str:
    if not ids:
        return "matches nothing in the catalogue"
    more = f", ... ({len(ids)} in all)" if len(ids) > n else ""
    return ", ".join(ids[:n]) + more


def vocabulary(domain) -> dict:
    """{section: [(name, what it is and matches), ...]} for tags, categories, components and styles."""
    items = _items(domain)
    tags = [(t, f"{desc}; {_few(_matches(items, t))}") for t, desc in domain.tags]
    cats = [(c, f"{desc}; {_few(_matches(items, c))}") for c, desc in domain.categories]
    used = {c: [t.id for t in domain.tasks if c in t.components] for c in (x.id for x in domain.components)}
    comps = [(c.id, f"{c.text} ({c.kind}; groups: {', '.join(c.groups) or '-'}; tasks: {', '.join(used[c.id]) or '-'})")
             for c in domain.components]
    groups: dict = {"all": [c.id for c in domain.components]}
    for c in domain.components:
        for g in (*c.groups, c.kind, *(("food",) if c.kind != "beverage" else ())):
            groups.setdefault(g, []).append(c.id)
    comps += [(g, f"group: {', '.join(ids)}") for g, ids in sorted(groups.items())]
    styles = [(s.id, s.text) for s in domain.styles]
    return {"tags": tags, "categories": cats, "components": comps, "styles": styles}
