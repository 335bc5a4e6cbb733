"""Row prompts for the trainers: the student's prompt left-truncated to `max_length` less the completion
with the project's `chat.fit` (whole oldest steps dropped, never the last; never silently: the row says
`truncated`, and the summary counts it).
"""

from __future__ import annotations

from ..llm.chat import count, fit, render
from ..llm.prompts import Prompt


def drop_oldest(prompt: Prompt, omit: int) -> Prompt:
    """The prompt without its `omit` oldest (action, observation) pairs (system and opening user message
    kept)."""
    head, body = prompt.messages[:2], prompt.messages[2:]
    return Prompt((*head, *body[2 * omit:]), prompt.prefix, prompt.omitted + omit)


def fit_row(tokenizer, prompt: Prompt, completion_tokens: int, max_length: int | None) -> tuple:
    """(prompt, prompt tokens, truncated): the prompt cut from the left so that it and `completion_tokens`
    fit `max_length` (None: no limit)."""
    budget = None if max_length is None else max(max_length - completion_tokens, 1)
    out = fit(tokenizer, lambda omit: drop_oldest(prompt, omit), budget)
    return out, count(tokenizer, render(tokenizer, out)), out.omitted > prompt.omitted


def completion_tokens(tokenizer, *texts) -> int:
    """Tokens of the longest completion (with the end token the chat template adds)."""
    return max(len(tokenizer(t, add_special_tokens=False)["input_ids"]) for t in texts if t is not None) + 1
