"""Rows as token ids, exactly as the planner reads and writes them, and every row's length checked.

    enc = Encoder(tokenizer)
    ids = enc.prompt(messages)                     # the rendered prompt's ids (chat template + "Action:")
    done = enc.completion(ids, "Look for eggs")    # the action's ids and the end token
    kept, long = check_lengths(rows, 1024)         # no row is cut or dropped without being reported

The trainers hand TRL pre-tokenized rows (TRL 1.x re-tokenizes text rows through the chat template, drops
a row whose prompt alone reaches `max_length` and cuts the end of the others, silently). Here the prompt is
`chat.render` of the row's messages with the planner's `Action: ` prefix, healed like generation
(`boundary.split_tail`: trailing spaces a tokenizer merges into the next word move to the completion), and
the completion is the action's tokens then the end-of-sequence token the model stops at: the model is
trained on the very tokens it reads and writes when it plays. A rejected completion given as the ids the
student generated (`rejected_ids`) is taken as it is.
"""

from __future__ import annotations

from dataclasses import dataclass

from ...llm.boundary import split_tail
from ...llm.chat import encode, render
from ...llm.prompts import ACTION_PREFIX, Prompt

IGNORE = -100  # label of a token the SFT loss skips


@dataclass(frozen=True)
class PromptIds:
    """A rendered prompt's ids and the trailing spaces moved into its completions (`tail`)."""

    ids: tuple
    tail: str = ""


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

    @property
    def length(self) -> int:
        """Tokens of the prompt and the longer completion (what must fit `max_length`)."""
        return len(self.prompt) + max(len(self.chosen), len(self.rejected or ()))

    def preference(self) -> dict:
        """The row as TRL's DPO collator takes it."""
        return {"prompt_ids": list(self.prompt), "chosen_ids": list(self.chosen), "rejected_ids": list(self.rejected)}

    def supervised(self) -> dict:
        """The row as TRL's SFT collator takes it (labels: the completion only)."""
        return {"input_ids": list(self.prompt + self.chosen),
                "labels": [IGNORE] * len(self.prompt) + list(self.chosen)}


class Encoder:
    """Token ids of prompts and completions for one tokenizer."""

    def __init__(self, tokenizer):
        self.tok = tokenizer
        if tokenizer.eos_token_id is None:
            raise ValueError("the tokenizer has no end-of-sequence token: the trained model could not stop")

    def prompt(self, messages, prefix: str = ACTION_PREFIX) -> PromptIds:
        """The prompt the planner sends: the messages through the chat template with the generation prompt,
        then `prefix`, healed at a token boundary."""
        text = render(self.tok, Prompt(tuple(dict(m) for m in messages), prefix))
        h = split_tail(self.tok, text)
        return PromptIds(tuple(encode(self.tok, h.head)), h.tail)

    def completion(self, prompt: PromptIds, action: str) -> tuple:
        """The action's ids after the prompt (healed spaces first), then the end token."""
        ids = self.tok(prompt.tail + action, add_special_tokens=False)["input_ids"]
        return (*ids, self.tok.eos_token_id)


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
