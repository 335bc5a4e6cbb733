"""Lark text from the grammar index: a static base per (task, level, variant), emitted once and
cached, plus the entity terminals of a state, re-emitted incrementally as the agent observes more.

Written by the two rules of notes/constrained-decoding.md: every space is its own piece
(`"Move" " " thing`), and free-text regexes carry no length bound (bound with max_new_tokens).
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from .index import GrammarIndex, Lit, Slot

LEVELS = ("syntax", "observed", "typed")
VARIANTS = ("default", "never_ask", "ask_only")
QUESTION_SETS = ("free", "bank")  # `Ask` takes any quoted text, or one of the domain's own questions

QUESTION = r'/"[^"\\\x00-\x1F\x7F]+"/'
RESULT = r"/[a-z][a-z0-9_]*/"
NAME = r"/[a-z][a-z0-9_]*/"
QUERY = r"/[a-z]+( [a-z]+)*/"

# slot kind -> the rule or terminal it is written as, per level
_SLOT_SYMBOL = {
    "syntax": {"entity": "NAME", "content": "NAME", "thing": "NAME"},
    "observed": {"entity": "OBSERVED", "content": "OBSERVED", "thing": "OBSERVED"},
    "typed": {"entity": "ENTITY", "content": "CONTENT", "thing": "thing"},
}
_FIXED_SYMBOL = {"result": "RESULT", "verb": "VERB", "question": "QUESTION"}


@dataclass(frozen=True)
class Observed:
    """What the agent may name in a state: entity ids (layout, found objects, results it made) and
    content names (substances and portions it has seen)."""

    entities: frozenset
    contents: frozenset


def quote(text: str) -> str:
    """A Lark string literal (JSON escaping is a subset Lark reads)."""
    return json.dumps(text, ensure_ascii=False)


def alternatives(names) -> str:
    """Literal alternatives, reverse-sorted so that an id is listed before its prefixes (egg_10, egg_1)."""
    return " | ".join(quote(n) for n in sorted(names, reverse=True))


def _lit(piece: Lit) -> str:
    if not piece.alts:
        return quote(piece.text)
    return "(" + " | ".join(quote(t) for t in (piece.text, *piece.alts)) + ")"


def _symbol(slot: Slot, level: str, form_verbs: str) -> str:
    if slot.kind == "verb":
        return form_verbs
    if slot.kind == "query":
        return "QUERY" if level == "syntax" else "CATEGORY"
    return _FIXED_SYMBOL.get(slot.kind) or _SLOT_SYMBOL[level][slot.kind]


def _verb_terminal(verbs, exclude=()) -> str:
    names = [v for v in verbs if v not in exclude]
    return alternatives(names + [v[:1].upper() + v[1:] for v in names])


@dataclass(frozen=True)
class Base:
    """The static part of one grammar: everything but the entity terminals (and the action list,
    which drops actions whose slots have nothing to name at the typed level)."""

    header: str
    rules: dict  # action id -> rule text
    kinds: dict  # action id -> slot kinds it needs
    static: str  # verb, category and free-text terminals
    level: str
    variant: str
    questions: str = "free"


def question_terminal(index: GrammarIndex, questions: str = "free") -> str:
    """The `QUESTION` terminal: any quoted text (`free`), or one of the domain's questions, quotes included
    (`bank`: for a student too small to word a question, it chooses one; docs/grammar.md)."""
    if questions not in QUESTION_SETS:
        raise ValueError(f"unknown question set '{questions}' (question sets: {', '.join(QUESTION_SETS)})")
    if questions == "free":
        return QUESTION
    if not index.questions:
        raise ValueError("--question-set bank: the domain's choices ask no questions (no `ask:` in its recipes)")
    return alternatives(f'"{q}"' for q in index.questions)


def _form_text(form, level: str, verb_names: dict) -> str:
    parts = []
    for p in form.pieces:
        if parts:
            parts.append('" "')
        parts.append(_lit(p) if isinstance(p, Lit) else _symbol(p, level, verb_names.get(form.exclude_verbs, "VERB")))
    return " ".join(parts)


def verb_terminals(index: GrammarIndex) -> tuple[dict, list]:
    """(exclusion set -> terminal name, emitted lines) of the verb terminals: `VERB`, and one `VERB_n`
    per distinct set of verbs a freeform form does not take."""
    names, lines = {frozenset(): "VERB"}, [f"VERB: {_verb_terminal(index.verbs)}"]
    excl = sorted({f.exclude_verbs for a in index.actions for f in a.forms if f.exclude_verbs}, key=sorted)
    for i, ex in enumerate(excl, 1):
        names[ex] = f"VERB_{i}"
        lines.append(f"// VERB_{i}: the verbs less {', '.join(sorted(ex))} (a dedicated action owns that reading)")
        lines.append(f"VERB_{i}: {_verb_terminal(index.verbs, ex)}")
    return names, lines


def _wanted(index: GrammarIndex, variant: str) -> list:
    if variant == "ask_only":
        return [a for a in index.actions if a.id == "ask"]
    if variant == "never_ask":
        return [a for a in index.actions if a.id != "ask"]
    return list(index.actions)


def build_base(index: GrammarIndex, level: str = "observed", variant: str = "default", title: str = "",
               questions: str = "free") -> Base:
    """The static part of a grammar for a level, variant and question set (`title` goes into the header
    comment)."""
    if level not in LEVELS:
        raise ValueError(f"unknown level '{level}' (levels: {', '.join(LEVELS)})")
    if variant not in VARIANTS:
        raise ValueError(f"unknown variant '{variant}' (variants: {', '.join(VARIANTS)})")
    verb_names, verb_lines = verb_terminals(index)
    actions = _wanted(index, variant)
    rules = {a.id: f"{a.id}: " + "\n    | ".join(_form_text(f, level, verb_names) for f in a.forms)
             for a in actions}
    used = {k for a in actions for k in a.kinds}
    static = []
    if "verb" in used:
        static += verb_lines
    if "query" in used:
        static.append(f"QUERY: {QUERY}" if level == "syntax" else f"CATEGORY: {alternatives(index.categories)}")
    static += [f"{name}: {regex}" for name, kind, regex in
               (("QUESTION", "question", question_terminal(index, questions)), ("RESULT", "result", RESULT))
               if kind in used]
    if level == "syntax" and used & {"entity", "content", "thing"}:
        static.append(f"NAME: {NAME}")
    if level == "typed" and "thing" in used:
        static.append("?thing: ENTITY | CONTENT")
    header = (f"// adaptbench action grammar (generated: adapt grammar build; do not edit)\n"
              f"// spec {index.spec_hash} · level {level} · variant {variant}"
              + (" · questions bank" if questions == "bank" else "") + (f" · {title}" if title else ""))
    return Base(header, rules, {a.id: a.kinds for a in actions}, "\n".join(static), level, variant, questions)


def usable_actions(base: Base, terminals) -> list:
    """The wanted actions whose slots can be filled in this state (at the typed level an action with a
    content slot is left out, rule and all, until some content has been observed)."""
    missing = {"content"} if base.level == "typed" and "CONTENT" not in terminals else set()
    return [a for a in base.rules if not (set(base.kinds[a]) & missing)]
