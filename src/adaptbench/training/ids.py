"""The token ids of a row's rejected answer: what the student generated, not a re-tokenization of its
text (on-policy data; docs/training-data.md).

    ids, is_canonical = rejected_turn_ids(tokenizer, prompt, action, decision.stats)

A DPO trainer (TRL's `DPOTrainer`) tokenizes a conversational row as prompt ids (the chat template with
the generation prompt) followed by completion ids (everything the template writes after it: the
assistant turn's content and its end). For the rejected answer the content is `Action: ` and the
student's action, and its ids here are the prefix's tokens as the student's prompt held them, then the
generated ids, then the template's end of the turn — the same layout, with the ids the student took
where a constrained decoder may have split the text differently from the tokenizer.
"""

from __future__ import annotations

from ..llm.prompts import ACTION_PREFIX


def _ids(tokenizer, text: str) -> list:
    return tokenizer(text, add_special_tokens=False)["input_ids"]


def rejected_turn_ids(tokenizer, prompt, action: str, stats: dict | None) -> tuple:
    """(ids, canonical) of the assistant turn `ACTION_PREFIX + action` after the rendered `prompt`
    (a `Prompt`), with the generated ids (`stats["token_ids"]`, begun after the healed prefix when
    `stats["healed"]` says so) in place of the action's tokens; canonical: whether they equal the
    template's own tokenization of the turn. (None, None) when the step recorded no ids or the chat
    template renders the prompt differently once an answer follows it."""
    generated = list((stats or {}).get("token_ids") or ())
    if not generated:
        return None, None
    messages = [dict(m) for m in prompt.messages]
    opening = tokenizer.apply_chat_template(messages, tokenize=False, add_generation_prompt=True)
    content = ACTION_PREFIX + action
    full = tokenizer.apply_chat_template(messages + [{"role": "assistant", "content": content}], tokenize=False)
    if not full.startswith(opening) or not full[len(opening):].startswith(content):
        return None, None
    turn = full[len(opening):]
    from ..llm.chat import end_token

    if generated[-1] in {end_token(tokenizer), tokenizer.eos_token_id}:
        generated = generated[:-1]
    healed = (stats or {}).get("healed") or ""
    head = ACTION_PREFIX[:len(ACTION_PREFIX) - len(healed)] if healed else ACTION_PREFIX
    ids = _ids(tokenizer, head) + generated + _ids(tokenizer, turn[len(content):])
    return ids, ids == _ids(tokenizer, turn)
