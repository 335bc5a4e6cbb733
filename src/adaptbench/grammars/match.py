"""The structural grammar (`parser.structural_text`) read with regular expressions: the same language —
the action forms of the grammar index, single spaces, `NAME`/`RESULT` identifiers, any word in a verb
slot less the verbs a dedicated action owns — matched in microseconds instead of a lark Earley parse
(~10 ms a string). The compiler checks recipe steps with it when a spec compiles; tests hold it to the
lark parser's verdicts (tests/grammars/test_match.py).

    matcher = FormMatcher(index.actions)
    matcher.match("Move pan_0 to stove_0")   # Match('move', (('x', 'pan_0'), ('y', 'stove_0')))
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from .emit import NAME, QUERY, QUESTION, RESULT
from .index import Lit, Slot

_TERMINAL = {"entity": NAME, "content": NAME, "thing": NAME, "result": RESULT, "query": QUERY,
             "question": QUESTION}


@dataclass(frozen=True)
class Match:
    """A matched action: its id and slot values by name (the fields of `parse.Parsed`, without lark)."""

    action: str
    slots: tuple  # ((slot name, text), ...) in form order


def _regex(lark_regex: str) -> str:
    return lark_regex[1:-1]  # "/.../" -> "..."


def _verb(excluded) -> str:
    if not excluded:
        return r"[^\W\d_]+"
    alts = "|".join(re.escape(w) for w in sorted(excluded))
    return rf"(?!(?:{alts})(?![^\W\d_]))[^\W\d_]+"


def _piece(p, excluded) -> str:
    if isinstance(p, Lit):
        return "(?:" + "|".join(re.escape(t) for t in (p.text, *p.alts)) + ")"
    body = _verb(excluded) if p.kind == "verb" else _regex(_TERMINAL[p.kind])
    return f"(?P<{p.name}>{body})"


def form_pattern(form) -> re.Pattern:
    """The regular expression of one form (full match)."""
    return re.compile(" ".join(_piece(p, form.exclude_verbs) for p in form.pieces))


class FormMatcher:
    """Reads action text with the structural grammar's forms: the action id and its slot strings."""

    def __init__(self, actions):
        self.forms = [(a.id, a.slots, f, form_pattern(f)) for a in actions for f in a.forms]

    def match(self, text: str) -> Match | None:
        """The action `text` reads as, or None when no form accepts it."""
        for aid, slots, _form, pattern in self.forms:
            m = pattern.fullmatch(text)
            if m:
                return Match(aid, tuple((s, m.group(s)) for s in slots))
        return None

    def shapes(self) -> list:
        """(action id, the form written with its slot names: `Move {x} to {y}`) for every form."""
        return [(aid, " ".join(p.text if isinstance(p, Lit) else "{" + p.name + "}" for p in form.pieces))
                for aid, _slots, form, _ in self.forms]

    def keywords(self) -> set:
        """The first words of the forms that start with a literal (`Move`, `Pour`, `Cook` ...)."""
        return {form.pieces[0].text for _, _, form, _ in self.forms if isinstance(form.pieces[0], Lit)}


def slot_kinds(actions) -> dict:
    """Action id -> {slot name: kind}."""
    return {a.id: {p.name: p.kind for f in a.forms for p in f.pieces if isinstance(p, Slot)} for a in actions}
