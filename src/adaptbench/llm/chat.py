"""Rendering prompts through the model's chat template, and left-truncation to a token budget.

    text = render(tokenizer, prompt)              # chat template + generation prompt + prefix
    prompt = fit(tokenizer, build, budget=4096)   # build(omit) -> Prompt; oldest history dropped first

`fit` keeps the system message, the opening user message (which then says how many steps were left
out) and the last step, and drops whole (action, observation) pairs from the oldest until the rendered
prompt fits.
"""

from __future__ import annotations

from collections.abc import Callable

from .prompts import Prompt

ROLES = ("system", "user", "assistant")


def check_roles(messages) -> None:
    """Raise ValueError unless the messages use the standard roles only and alternate user/assistant
    after an optional system message (what every chat template accepts)."""
    roles = [m["role"] for m in messages]
    bad = sorted(set(roles) - set(ROLES))
    if bad:
        raise ValueError(f"non-standard chat roles {bad}: use {', '.join(ROLES)} only")
    body = roles[1:] if roles and roles[0] == "system" else roles
    for i, r in enumerate(body):
        if r != ("user" if i % 2 == 0 else "assistant"):
            raise ValueError(f"chat roles must alternate user/assistant after the system message (got {roles})")


def render(tokenizer, prompt: Prompt) -> str:
    """The prompt as text: the messages through the tokenizer's chat template with the generation
    prompt, followed by the prefix the completion continues."""
    check_roles(prompt.messages)
    text = tokenizer.apply_chat_template(list(prompt.messages), tokenize=False, add_generation_prompt=True)
    return text + prompt.prefix


def count(tokenizer, text: str) -> int:
    """Tokens in a rendered prompt (the chat template already holds the special tokens)."""
    return len(tokenizer(text, add_special_tokens=False)["input_ids"])


def history_steps(prompt: Prompt) -> int:
    """How many history steps (assistant turns) a prompt holds."""
    return sum(1 for m in prompt.messages if m["role"] == "assistant")


def fit(tokenizer, build: Callable[[int], Prompt], budget: int | None) -> Prompt:
    """The prompt with the fewest oldest steps left out (`build(omit)`) whose rendering fits `budget`
    tokens, never the last step; with no budget the full prompt, and when even the shortest does not
    fit, the shortest (its `meta['over_budget']` then says by how much)."""
    full = build(0)
    if budget is None:
        return full
    n = history_steps(full)
    if count(tokenizer, render(tokenizer, full)) <= budget:
        return full
    lo, hi = (1, n - 1) if n > 1 else (0, 0)  # the last step (its observation) is always kept
    while lo < hi:
        mid = (lo + hi) // 2
        if count(tokenizer, render(tokenizer, build(mid))) <= budget:
            hi = mid
        else:
            lo = mid + 1
    out = build(hi)
    over = count(tokenizer, render(tokenizer, out)) - budget
    if over > 0:
        out.meta["over_budget"] = over
    return out
