"""Prompts that end on a token boundary of the model's tokenizer (token healing of a trailing space).

The agents' prompts end with a prefix the completion continues: `Action: `, `Thought: `. Most real
tokenizers (GPT-2 style byte-level BPE, SentencePiece's Metaspace) put the space at the front of the
next word (` Look`), so a prompt ending in a space ends on a lone space token the model has hardly seen
before a word: SmolLM2's next-token distribution after `Action: ` is 72% newline with no action word in
its top 8, and the constrained decoder is left with unnatural tokens (`Look` without its space).

    heal = split_tail(tokenizer, text)            # Healing(head="...Action:", tail=" ") or tail=""
    outs = generate(backend, requests)            # every request healed, completions un-healed

`split_tail` checks, once per tokenizer and last line, whether the text's trailing spaces stay a token
boundary when a word follows (the tiny tokenizer keeps the space with the word before it: nothing to
heal). When they do not, the spaces move from the prompt into the completion: the prompt ends at
`Action:`, the grammar requires the spaces first (`start: " " <the original start>`; an unconstrained
request gets `start: " " <one line>`), and the spaces are cut from the text that comes back. The model
then reads the tokens it would read in `Action: Look for eggs`, and the constrained first-token
distribution is the unconstrained one restricted to the grammar. Both backends get the healed requests
(`generate` wraps `backend.generate`), and `score` heals continuations the same way.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

from .backend import Completion, Request, Scored, continuation_ids

PROBES = ("Look", "Ask", "I", "a", '"', "1")  # words that may follow a prefix
_START = re.compile(r"(?m)^start(\s*):")
HEALED_START = "adapt_healed_start"


@dataclass(frozen=True)
class Healing:
    """A rendered prompt split into the text the model reads (`head`) and the trailing spaces the
    completion must begin with (`tail`, "" when the prompt already ends on a token boundary)."""

    head: str
    tail: str = ""


def _ids(tokenizer, text: str) -> list:
    return tokenizer(text, add_special_tokens=False)["input_ids"]


def ends_on_boundary(tokenizer, line: str) -> bool:
    """Whether `line`'s tokens stay the opening tokens of `line + word` for every probe word (the last
    token is not merged into what follows)."""
    ids = _ids(tokenizer, line)
    return all(_ids(tokenizer, line + w)[:len(ids)] == ids for w in PROBES)


def split_tail(tokenizer, text: str) -> Healing:
    """Split a prompt's trailing spaces off when the tokenizer would merge them into the next word.
    The answer depends on the last line only and is kept on the tokenizer object."""
    head = text.rstrip(" ")
    tail = text[len(head):]
    if not tail:
        return Healing(text)
    line = text[text.rfind("\n") + 1:]
    memo = tokenizer.__dict__.setdefault("_adapt_boundary", {})
    if line not in memo:
        memo[line] = ends_on_boundary(tokenizer, line)
    return Healing(text) if memo[line] else Healing(head, tail)


def _literal(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def healed_grammar(grammar: str | None, tail: str) -> str:
    """The grammar that requires `tail` before what `grammar` accepts (None: one line of any text,
    ending at its newline or at the end of generation)."""
    if grammar is None:
        return f"start: {_literal(tail)} REST\nREST: /[^\\n]*\\n?/\n"
    if not _START.search(grammar):
        raise ValueError("cannot heal a grammar without a `start:` rule")
    return _START.sub(lambda m: f"start: {_literal(tail)} {HEALED_START}\n{HEALED_START}{m.group(1)}:", grammar, count=1)


def heal(tokenizer, request: Request) -> tuple:
    """(the request to send, the tail its completion will begin with)."""
    h = split_tail(tokenizer, request.prompt)
    if not h.tail:
        return request, ""
    validate = request.validate
    checked = None if validate is None else (lambda text, v=validate, t=h.tail: v(_cut(text, t)))
    return replace(request, prompt=h.head, grammar=healed_grammar(request.grammar, h.tail), validate=checked), h.tail


def _cut(text: str, tail: str) -> str:
    return text[len(tail):] if text.startswith(tail) else text.lstrip(" ")


def unheal(out: Completion, tail: str, constrained: bool) -> Completion:
    """The completion as the unhealed request would have returned it: the tail cut off, `accepted` None
    for a request that had no grammar of its own."""
    if not tail:
        return out
    return replace(out, text=_cut(out.text, tail), accepted=out.accepted if constrained else None,
                   stats={**out.stats, "healed": tail})


def generate(backend, requests) -> list:
    """`backend.generate` with every request's prompt ending on a token boundary (see the module)."""
    healed = [heal(backend.tokenizer, r) for r in requests]
    outs = backend.generate([r for r, _ in healed])
    return [unheal(o, tail, r.grammar is not None) for o, (_, tail), r in zip(outs, healed, requests, strict=True)]


def score_group(backend, prompt: str, continuations) -> tuple:
    """The `score_ids` group (prompt ids, [completion ids, ...]) that `score` reads for these
    continuations of `prompt`: healed the same way (text continuations' ids end with the end token,
    `continuation_ids`; ids as they are)."""
    h = split_tail(backend.tokenizer, prompt)
    conts = [h.tail + c if h.tail and isinstance(c, str) else c for c in continuations]
    return backend.encode(h.head if h.tail else prompt), [continuation_ids(backend.tokenizer, c) for c in conts]


def score(backend, prompt: str, continuations, dtype: str | None = None) -> list:
    """`backend.score` with the prompt's trailing spaces moved to the front of every text continuation
    when the tokenizer merges them into the next word: the log-probabilities are those of the
    continuation's own tokens (` Look`, ` for`, ` eggs`, the end token), read after the prompt the model
    would see in the text. A continuation of token ids (a completion's `token_ids`) is scored after the
    prompt its request was generated from: the healed one, whose spaces its ids begin with."""
    h = split_tail(backend.tokenizer, prompt)
    if not h.tail:
        return backend.score(prompt, continuations, dtype=dtype)
    got = backend.score(h.head, [h.tail + c if isinstance(c, str) else c for c in continuations], dtype=dtype)
    return [Scored(c, s.logprobs, s.token_ids) if isinstance(c, str) else s
            for c, s in zip(continuations, got, strict=True)]
