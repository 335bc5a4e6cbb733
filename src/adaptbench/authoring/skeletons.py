"""`adapt new persona ID` and `adapt new task ID`: commented skeletons that validate as written."""

from __future__ import annotations

import re
from pathlib import Path

_ID = re.compile(r"^[a-z][a-z0-9_]*$")


def skeleton_path(spec, kind: str, ident: str) -> Path:
    """Where the skeleton goes: spec/personas/ID.yaml or spec/tasks/ID.yaml; ValueError on a bad id."""
    if not _ID.match(ident):
        raise ValueError(f"'{ident}' is not a valid id (snake_case: lowercase letters, digits, _)")
    return Path(spec) / ("personas" if kind == "persona" else "tasks") / f"{ident}.yaml"


def skeleton_text(spec, kind: str, ident: str) -> str:
    """The skeleton's YAML for the spec at `spec` (which must compile: names are taken from it)."""
    from ..compiler import load_domain

    domain = load_domain(spec)
    pool = domain.persona if kind == "persona" else {**domain.task, **{c.id: c for c in domain.components}}
    if ident in pool:
        raise ValueError(f"a {kind} '{ident}' already exists")
    return _persona(domain, ident) if kind == "persona" else _task(domain, ident)


def _place(domain) -> str:
    places = [e.id for e in domain.entities if "dining_place" in e.tags]
    return "dining_place" if places else (domain.entities[0].id if domain.entities else "kitchen")


def _persona(domain, ident: str) -> str:
    number = max((p.number for p in domain.personas), default=0) + 1
    comp = domain.tasks[0].components[0] if domain.tasks else "all"
    return f"""\
# Persona {ident}. Format: docs/authoring.md ("Add a persona"); rule language: docs/rules.md;
# names a rule may use: `adapt vocab`. Check it with `adapt validate`, then write fixtures for it
# (docs/fixtures.md) and run `adapt test`.
{"id: " + ident:<34}# must equal the file name
{"name: " + ident.replace("_", " ").title():<34}# TODO: the persona's name
{"number: " + str(number):<34}# unique; the next free number
description: TODO one line on who this persona is
preferences:
  # One entry per preference. `rule` is what the verifier checks; `text` is what the persona would say;
  # the offline user answers a question that uses the `topics` words with `answer`.
  - id: served_at_the_table       # TODO: rename; unique within the persona
    text: TODO Serve my breakfast at the table
    rule: "for {comp}: it served at {_place(domain)}"  # TODO: e.g. "for coffee: it has no sweetener"
    topics: [table, where, serve]
    answer: TODO Please serve it at the table.
"""


def _completion(domain) -> str:
    tags = dict(domain.tags)
    return "it has edible" if "edible" in tags else f"it has {domain.categories[0][0]}"


def _task(domain, ident: str) -> str:
    comp = domain.components[0].id if domain.components else ident
    return f"""\
# Task {ident}. Format: docs/authoring.md ("Add a task"); completion rules: docs/rules.md; recipes (how the
# scripted agents make a component): docs/recipes.md. A task lists components; a served dish completes a
# component when its completion rule holds for it.
tasks:
  - id: {ident}
    text: TODO Make {ident.replace('_', ' ')} for breakfast   # what the agent is told
    {"components: [" + ident + "]":<31}# TODO: this file's new component, and/or existing ones ({comp}, ...)

components:
  - id: {ident}
    text: {ident.replace('_', ' ')}
    kind: savory                   # sweet | savory | beverage: persona rules target kinds
    groups: []                     # extra groups rules can target (see `adapt vocab --components`)
    {"completion: " + _completion(domain):<31}# TODO: what a served dish must have, e.g. "it has heated egg"
    # requires: [egg, cookware]    # classes every sampled scene keeps at least one of

# recipes:                         # TODO: without one the scripted agents cannot make it (docs/recipes.md)
#   - id: {ident}
#     component: {ident}
#     serve: plate
#     choices:
#       - {{id: plate, ask: What should I serve it on?, options: [plate_0]}}
#     steps:
#       - Move {{plate}} to table_0
"""


_UNSEEN = re.compile(r"^(?P<head>.*\bunseen:\s*\[)(?P<ids>[^\]]*)(?P<tail>\].*)$")


def add_to_splits(spec, ident: str) -> str:
    """Put a new persona in the split with the fewest unseen personas (every persona is unseen in exactly one
    split, D602), editing spec/splits.yaml in place; returns what was done, or what the author must do."""
    path = Path(spec) / "splits.yaml"
    if not path.is_file():
        return ""
    lines = path.read_text().splitlines(keepends=True)
    found = [(len([x for x in m["ids"].split(",") if x.strip()]), i, m) for i, line in enumerate(lines)
             if (m := _UNSEEN.match(line.rstrip("\n")))]
    if not found:
        return f"to do: add {ident} to the `unseen` list of one split in {path} (every persona is unseen in exactly one)"
    _, i, m = min(found, key=lambda f: (f[0], f[1]))
    ids = m["ids"].rstrip()
    lines[i] = f"{m['head']}{ids}{', ' if ids.strip() else ''}{ident}{m['tail']}\n"
    path.write_text("".join(lines))
    return f"changed {path}: added {ident} to the unseen personas of a split (line {i + 1})"
