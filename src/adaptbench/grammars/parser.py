"""The simulator's action parser: the structural grammar of a domain (syntax level, default variant:
any identifier in entity slots, so an unseen id still reaches binding and its "you have not found it"
message) parsed with python-lark, results cached by text in a bounded LRU owned by the parser.

Earley, not LALR: the structural grammar is not LALR(1) (a keyword that is also a freeform verb, e.g.
`Heat`, starts both `heat` and `freeform_object`, and spaces are separate tokens, so one token of
lookahead cannot tell them apart; lark's contextual lexer also cannot lex `Heat` as both). The
keyword/verb readings are resolved in the grammar itself (docs/grammar.md), so every accepted string
has exactly one parse and the Earley result is unambiguous.
"""

from __future__ import annotations

import dataclasses
import re
from functools import lru_cache

from .emit import Observed, build_base, verb_terminals
from .index import GrammarIndex, Lit, Slot
from .parse import Parsed, lark_parser, parse
from .state import StateGrammar

CACHE_SIZE = 16384


def _rest(form) -> tuple:
    return tuple(p.text if isinstance(p, Lit) else "<slot>" for p in form.pieces[1:])


def _is_freeform(form) -> bool:
    return isinstance(form.pieces[0], Slot) and form.pieces[0].kind == "verb"


def _keywords_like(index: GrammarIndex, form) -> frozenset:
    """Dedicated keywords (every accepted spelling) whose form has the same shape after its first word as
    the freeform form `form`: with any word allowed as the verb, these strings would read both ways."""
    return frozenset(t for a in index.actions for f in a.forms
                     if isinstance(f.pieces[0], Lit) and _rest(f) == _rest(form)
                     for t in (f.pieces[0].text, *f.pieces[0].alts))


def keyword_collisions(index: GrammarIndex) -> dict:
    """(action id, form index) of each freeform form -> the keywords its verb slot does not take."""
    return {(a.id, i): sorted(_keywords_like(index, f)) for a in index.actions for i, f in enumerate(a.forms)
            if _is_freeform(f)}


def _word(excluded) -> str:
    if not excluded:
        return r"/[^\W\d_]+/"
    alts = "|".join(re.escape(w) for w in sorted(excluded))
    return rf"/(?!(?:{alts})(?![^\W\d_]))[^\W\d_]+/"


def structural_text(index: GrammarIndex) -> str:
    """The Lark text of the structural grammar: the syntax level (the committed `grammars/syntax.lark`
    less its layout) with any word in a verb slot, so an unknown verb reaches binding ("'zorp' is not a
    verb I know"), less, per freeform form, the dedicated keywords that would make a string read two
    ways (`Chop x to get y` is the `chop` action, `Cook items in x to get y` is `cook`; `chop the
    object x to get y` stays freeform). Python-regex lookahead: for lark only, never sent to a
    decoding engine."""
    actions = tuple(dataclasses.replace(a, forms=tuple(
        dataclasses.replace(f, exclude_verbs=_keywords_like(index, f)) if _is_freeform(f) else f
        for f in a.forms)) for a in index.actions)
    ix = dataclasses.replace(index, actions=actions)
    base = build_base(ix, "syntax")
    names, _ = verb_terminals(ix)
    lines = [ln for ln in base.static.splitlines() if not re.match(r"(//\s*)?VERB(_\d+)?:", ln)]
    static = "\n".join([*(f"{name}: {_word(ex)}" for ex, name in sorted(names.items(), key=lambda kv: kv[1])),
                        *lines])
    return StateGrammar(dataclasses.replace(base, static=static), Observed(frozenset(), frozenset())).text


class ActionParser:
    """Parses action text to (action id, slots) with the structural grammar; built lazily (a lark
    Earley parser over this grammar costs ~0.9 s to build), one per domain index."""

    def __init__(self, index: GrammarIndex, cache_size: int = CACHE_SIZE):
        self.index = index
        self.text = structural_text(index)
        self._lark = None
        self.parse = lru_cache(maxsize=cache_size)(self._parse)

    def _parse(self, text: str) -> Parsed | None:
        if self._lark is None:
            self._lark = lark_parser(self.text)
        return parse(self._lark, self.index, text)

    def cache_info(self):
        """Hits, misses and size of the text cache."""
        return self.parse.cache_info()
