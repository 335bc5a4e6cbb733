"""Row prompts for the trainers: the student's prompt shrunk to `max_length` less the completion without
ever losing what the user said.

A prompt that must shrink loses, oldest first, the observations of steps that were not questions (the
action stays, its observation becomes `ELIDED`), then those steps themselves; the system message, the
opening message (the task), every question with the user's answer, and the last step are always kept.
So a row never trains the student to act on an answer it cannot see. Never silently: the row says
`truncated`, `qa_kept` / `qa_total`, and the summary counts them.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..llm.chat import count, render
from ..llm.prompts import ACTION_PREFIX, Prompt

ELIDED = "(observation left out to fit the context)"
ASK = ACTION_PREFIX + "Ask"


@dataclass(frozen=True)
class Fitted:
    """A row's prompt after fitting: the prompt, its tokens, whether it was shrunk, and the questions
    (with their answers) kept out of those in the full prompt."""

    prompt: Prompt
    tokens: int
    truncated: bool
    qa_kept: int
    qa_total: int
    over: int = 0  # tokens over the budget with everything droppable gone (0: it fits)


def is_question(message: dict) -> bool:
    """Whether an assistant message is a question (`Action: Ask "..."`)."""
    return message["role"] == "assistant" and message["content"].lstrip().startswith(ASK)


def questions(prompt: Prompt) -> int:
    """Question steps in a prompt's history."""
    return sum(1 for m in prompt.messages[2:] if is_question(m))


def droppable(prompt: Prompt) -> list:
    """Indices (into `messages`) of the assistant turns that may shrink: every history step but the last
    and the questions, oldest first."""
    msgs = prompt.messages
    steps = [i for i in range(2, len(msgs), 2) if msgs[i]["role"] == "assistant"]
    return [i for i in steps[:-1] if not is_question(msgs[i]) and i + 1 < len(msgs)]


def shrink(prompt: Prompt, level: int) -> Prompt:
    """The prompt at shrink `level` (0: as it is; 1..m: the m droppable steps' observations elided
    oldest first; m+1..2m: those steps dropped oldest first, the rest still elided)."""
    idx = droppable(prompt)
    m = len(idx)
    elide, drop = set(idx[:min(level, m)]), set(idx[:max(0, level - m)])
    out = list(prompt.messages[:2])
    msgs = prompt.messages
    for i in range(2, len(msgs), 2):
        if i in drop:
            continue
        out.append(msgs[i])
        if i + 1 < len(msgs):
            out.append({**msgs[i + 1], "content": ELIDED} if i in elide else msgs[i + 1])
    return Prompt(tuple(out), prompt.prefix, prompt.omitted + len(drop), dict(prompt.meta))


def fit_prompt(tokenizer, prompt: Prompt, completion_tokens: int, max_length: int | None) -> Fitted:
    """The least-shrunk prompt that fits `max_length` with `completion_tokens`; when even the most shrunk
    does not fit, that one with `over` saying by how much (the caller refuses it: its task, questions and
    answers alone need more than the budget)."""
    total = questions(prompt)

    def tokens(p: Prompt) -> int:
        return count(tokenizer, render(tokenizer, p))

    full = tokens(prompt)
    budget = None if max_length is None else max_length - completion_tokens
    if budget is None or full <= budget:
        return Fitted(prompt, full, False, total, total)
    lo, hi = 1, 2 * len(droppable(prompt))
    if tokens(shrink(prompt, hi)) > budget:
        out = shrink(prompt, hi)
        n = tokens(out)
        return Fitted(out, n, hi > 0, questions(out), total, n - budget)
    while lo < hi:
        mid = (lo + hi) // 2
        if tokens(shrink(prompt, mid)) <= budget:
            hi = mid
        else:
            lo = mid + 1
    out = shrink(prompt, hi)
    return Fitted(out, tokens(out), True, questions(out), total)


def completion_tokens(tokenizer, *texts) -> int:
    """Tokens of the longest completion (with the end token the chat template adds)."""
    return max(len(tokenizer(t, add_special_tokens=False)["input_ids"]) for t in texts if t is not None) + 1
