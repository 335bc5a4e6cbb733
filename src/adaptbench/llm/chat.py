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


RENDERED = 64  # rendered prompts kept per tokenizer


def render(tokenizer, prompt: Prompt) -> str:
    """The prompt as text: the messages through the tokenizer's chat template with the generation
    prompt, followed by the prefix the completion continues. The last `RENDERED` renderings are kept on
    the tokenizer (a prompt is rendered while it is fitted to the budget, then again to generate)."""
    check_roles(prompt.messages)
    memo = tokenizer.__dict__.get("_adapt_rendered")
    if memo is None:
        from ..runtime.tables import LRU

        memo = tokenizer.__dict__["_adapt_rendered"] = LRU(RENDERED)
    key = tuple((m["role"], m["content"]) for m in prompt.messages)
    text = memo.get_or_build(key, lambda: tokenizer.apply_chat_template(list(prompt.messages), tokenize=False,
                                                                       add_generation_prompt=True))
    return text + prompt.prefix


ENCODED = 64  # rendered prompts whose token ids are kept per tokenizer
SEGMENTS = 8192  # text pieces between special tokens whose ids are kept per tokenizer
CHECKED = 8  # prompts encoded both ways before trusting piecewise encoding


def encode(tokenizer, text: str) -> list:
    """Token ids of a rendered prompt (no special tokens added: the chat template holds them).

    A step's prompt repeats the last one's system message and turns, so the text is cut at the
    tokenizer's added tokens (which it never merges across) and each piece's ids are remembered: only
    the new turns are tokenized. The first `CHECKED` prompts are also encoded whole; a tokenizer whose
    pieces do not add up (e.g. one that adds a prefix space to every piece) is then always encoded
    whole. The last `ENCODED` texts are remembered too: a prompt is counted while it is fitted to the
    budget and then encoded again by the backend. Returns a shared list: do not modify it."""
    state = _encoder(tokenizer)
    hit = state["texts"].get(text)
    if hit is not None:
        return hit
    if state["pieces"] is None:
        ids = _whole(tokenizer, text)
    else:
        ids = _pieces(tokenizer, state, text)
        if state["checked"] < CHECKED:
            state["checked"] += 1
            if ids != _whole(tokenizer, text):
                state["pieces"] = None
                ids = _whole(tokenizer, text)
    return state["texts"].put(text, ids)


def _whole(tokenizer, text: str) -> list:
    return tokenizer(text, add_special_tokens=False)["input_ids"]


def _encoder(tokenizer) -> dict:
    state = tokenizer.__dict__.get("_adapt_encoder")
    if state is None:
        import re

        from ..runtime.tables import LRU

        added = sorted(getattr(tokenizer, "added_tokens_encoder", {}), key=len, reverse=True)
        split = re.compile("(" + "|".join(map(re.escape, added)) + ")") if added else None
        state = tokenizer.__dict__["_adapt_encoder"] = {
            "texts": LRU(ENCODED), "pieces": LRU(SEGMENTS) if split else None, "split": split, "checked": 0,
            "ids": dict(getattr(tokenizer, "added_tokens_encoder", {}))}
    return state


def _pieces(tokenizer, state: dict, text: str) -> list:
    out: list = []
    memo, ids = state["pieces"], state["ids"]
    for k, piece in enumerate(state["split"].split(text)):
        if not piece:
            continue
        if k % 2:  # an added token
            out.append(ids[piece])
        else:
            out += memo.get_or_build(piece, lambda p=piece: _whole(tokenizer, p))
    return out


_MARK = "adaptbench-end-probe"


def end_token(tokenizer) -> int | None:
    """The token the chat template closes an assistant turn with (end-of-turn, such as `<|im_end|>` or
    `<|eot_id|>`, or EOS): the first special token the template writes after an assistant message's
    content; EOS when it writes none (None without EOS either). Kept on the tokenizer object."""
    memo = tokenizer.__dict__.setdefault("_adapt_end", [])
    if not memo:
        memo.append(_end_token(tokenizer))
    return memo[0]


def _end_token(tokenizer) -> int | None:
    messages = [{"role": "user", "content": "u"}, {"role": "assistant", "content": _MARK}]
    try:
        text = tokenizer.apply_chat_template(messages, tokenize=False)
    except Exception:  # noqa: BLE001 - a template that refuses this chat: fall back to EOS
        text = ""
    special = set(getattr(tokenizer, "all_special_ids", ())) | set(getattr(tokenizer, "added_tokens_decoder", {}))
    if _MARK in text:
        after = text[text.index(_MARK) + len(_MARK):]
        for t in tokenizer(after, add_special_tokens=False)["input_ids"]:
            if t in special:
                return t
    return tokenizer.eos_token_id


def count(tokenizer, text: str) -> int:
    """Tokens in a rendered prompt."""
    return len(encode(tokenizer, text))


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
