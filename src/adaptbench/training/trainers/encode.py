"""Rows as token ids, laid out as TRL lays out a conversational row, and every row's length checked.

    enc = Encoder(tokenizer)
    prompt, (chosen, rejected) = enc.row(messages, "Look for pan", "Look for eggs")
    kept, long = check_lengths(rows, 1024)         # no row is cut or dropped without being reported

The trainers hand TRL rows already in ids (TRL 1.x re-tokenizes text rows, drops a row whose prompt alone
reaches `max_length` and cuts the end of the others, silently). The layout is TRL's own for a conversational
row: the prompt is the chat template with the generation prompt (`chat.render`, no prefix), and a completion
is everything the template writes for the assistant turn `Action: <text>`: the prefix, the action, the
template's end of turn (e.g. `<|im_end|>` and its newline). That is the layout `adapt train data` gives the
ids the student generated (`rejected_token_ids`, docs/training-data.md), which are then taken as they are.
Prompt plus completion is the template's tokenization of the whole conversation, and the sequence the model
reads and writes when it plays (the healed `...Action:` prompt, then the action) is its prefix
(`tests/llm/test_trainers.py`). For a chat template that renders the prompt differently once an answer
follows it, the row falls back to the generation layout: the prompt rendered with the `Action: ` prefix and
healed as generation heals it (`boundary.split_tail`), the completion the action's ids and the end token.
`Encoder(tokenizer, layout="generation")` (`adapt train ... --layout generation`) takes that layout for every
row: for a student behaviour-cloned with the prefix in its prompt, which never writes `Action: ` or the
template's end of turn itself (docs/training.md: in TRL's layout they are ~40 nats of every completion, most
of an SFT term's loss, and 240 DPO updates on them broke the tiny student's cooking).
"""

from __future__ import annotations

from dataclasses import dataclass

from ...llm.boundary import split_tail
from ...llm.chat import encode, render
from ...llm.prompts import ACTION_PREFIX, Prompt
from .config import LAYOUTS

IGNORE = -100  # label of a token the SFT loss skips


@dataclass(frozen=True)
class Encoded:
    """One training row in ids: its key (persona, task, seed, interaction, step), the prompt, the chosen
    completion and, for preference rows, the rejected one."""

    key: tuple
    prompt: tuple
    chosen: tuple
    rejected: tuple | None = None
    truncated: bool = False
    generated_rejected: bool = False
    chosen_keep: tuple | None = None    # per completion token, 0 where the loss skips it (`--mask-forced`)
    rejected_keep: tuple | None = None

    @property
    def length(self) -> int:
        """Tokens of the prompt and the longer completion (what must fit `max_length`)."""
        return len(self.prompt) + max(len(self.chosen), len(self.rejected or ()))

    def preference(self) -> dict:
        """The row as TRL's DPO collator takes it; with keep masks, as `KeepMaskCollator` takes it."""
        out = {"prompt_ids": list(self.prompt), "chosen_ids": list(self.chosen), "rejected_ids": list(self.rejected)}
        if self.chosen_keep is not None:
            out |= {"chosen_keep": list(self.chosen_keep), "rejected_keep": list(self.rejected_keep)}
        return out

    def supervised(self) -> dict:
        """The row as TRL's SFT collator takes it (labels: the completion only, less what `chosen_keep` skips)."""
        keep = self.chosen_keep or (1,) * len(self.chosen)
        return {"input_ids": list(self.prompt + self.chosen),
                "labels": [IGNORE] * len(self.prompt) + [t if k else IGNORE for t, k in zip(self.chosen, keep, strict=True)]}


class Encoder:
    """Token ids of prompts and completions for one tokenizer."""

    def __init__(self, tokenizer, layout: str = "chat"):
        if layout not in LAYOUTS:
            raise ValueError(f"unknown row layout '{layout}' (layouts: {', '.join(LAYOUTS)})")
        self.tok, self.layout = tokenizer, layout
        if tokenizer.eos_token_id is None:
            raise ValueError("the tokenizer has no end-of-sequence token: the trained model could not stop")

    def _ids(self, text: str) -> list:
        return self.tok(text, add_special_tokens=False)["input_ids"]

    def turns(self, messages, actions) -> list | None:
        """The text the template writes after the generation prompt for each assistant turn
        `Action: <action>`; None when it renders the prompt differently once an answer follows."""
        messages = [dict(m) for m in messages]
        opening = render(self.tok, Prompt(tuple(messages), ""))
        out = []
        for a in actions:
            content = ACTION_PREFIX + a
            full = self.tok.apply_chat_template(messages + [{"role": "assistant", "content": content}], tokenize=False)
            if not full.startswith(opening) or not full[len(opening):].startswith(content):
                return None
            out.append(full[len(opening):])
        return out

    def row(self, messages, *actions) -> tuple:
        """(prompt ids, [completion ids of each action], True) in TRL's layout, or (..., False) in the
        generation layout: when the template does not allow TRL's (see the module), or when asked for
        (`layout="generation"`, `--layout generation`)."""
        msgs = tuple(dict(m) for m in messages)
        turns = self.turns(msgs, actions) if self.layout == "chat" else None
        if turns is not None:
            return tuple(encode(self.tok, render(self.tok, Prompt(msgs, "")))), [tuple(self._ids(t)) for t in turns], True
        h = split_tail(self.tok, render(self.tok, Prompt(msgs, ACTION_PREFIX)))
        ends = [(*self._ids(h.tail + a), self.tok.eos_token_id) for a in actions]
        return tuple(encode(self.tok, h.head)), ends, False


def action_of(message_list, prefix: str = ACTION_PREFIX) -> str:
    """The action text of a one-message completion `[{"role": "assistant", "content": "Action: ..."}]`."""
    if not message_list or message_list[-1].get("role") != "assistant":
        raise ValueError("a completion must be one assistant message")
    content = message_list[-1]["content"]
    if not content.startswith(prefix):
        raise ValueError(f"a completion must start with '{prefix}' (got {content[:40]!r})")
    return content[len(prefix):]


@dataclass(frozen=True)
class LongRow:
    """A row that does not fit `max_length`: its key and tokens."""

    key: tuple
    tokens: int
    prompt_tokens: int


def check_lengths(rows, max_length: int) -> tuple:
    """(rows that fit, LongRow of each that does not): nothing is cut, the caller refuses or reports."""
    kept, long = [], []
    for r in rows:
        if r.length <= max_length:
            kept.append(r)
        else:
            long.append(LongRow(r.key, r.length, len(r.prompt)))
    return kept, long


def key_text(key: tuple) -> str:
    """A row's key for messages: persona/task/seed N/interaction N/step N."""
    persona, task, seed, interaction, step = key
    return f"{persona}/{task}/seed {seed}/interaction {interaction}/step {step}"
