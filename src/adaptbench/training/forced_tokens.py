"""The loss only where a `bank` decoder chooses: a question's tokens that its grammar forces carry none.

Under `--question-set bank` an `Ask` names one of the domain's questions (`grammars.index.domain_questions`)
and the constrained decoder samples from the tokens the grammar allows: once `Ask "Any` is written, every
further token of *Any toppings, like fruit, nuts…?* is the only one allowed, and its probability under the
mask is 1 whatever the model's logits say. A likelihood loss on those tokens trains nothing the policy
uses, and for a student that never saw a question (the shipped one, cloned on episodes without them) it is
~15 nats a token over ~20 tokens a question: nearly all of an episode's loss and gradient, which breaks the
student's cooking within 50 updates (docs/training.md, twenty-second session). `mask_forced` drops the loss
on every token of a bank question's `Ask` action that the bank forces, keeping it where the decoder has a
choice to make: `Ask` itself (asking or acting), and each token where two bank questions part.
"""

from __future__ import annotations

from .pretrain import IGNORE


def question_trie(tokenizer, questions) -> dict:
    """A trie (nested dicts keyed by token id) of every `Ask "question"` action as the policy writes it: its
    tokens, then EOS."""
    root: dict = {}
    for q in questions:
        node = root
        for t in tokenizer(f'Ask "{q}"', add_special_tokens=False)["input_ids"] + [tokenizer.eos_token_id]:
            node = node.setdefault(t, {})
    return root


def forced(trie: dict, action: list) -> list:
    """For each token of one action (its ids, EOS last), whether the bank forces it: the trie node the
    tokens before it lead to has that token as its only child. All False when the action is not a bank
    question (it leaves the trie), and for the first token always (asking or acting is a choice)."""
    out, node = [], trie
    for i, t in enumerate(action):
        if t not in node:
            return [False] * len(action)
        out.append(i > 0 and len(node) == 1)
        node = node[t]
    return out


def completion_keep(ids, trie: dict, eos_id: int) -> tuple:
    """For a completion's ids (`Action: `, the action, the end of turn, as the trainers lay rows out), 1 at
    every token the loss should score and 0 at each token of a bank question that the bank forces (`forced`);
    all 1 when the completion holds no whole bank question."""
    ids = list(ids)
    for start in range(len(ids)):
        end = _question_end(ids, start, trie, eos_id)
        if end is not None:
            flags = [False] * start + forced(trie, ids[start:end]) + [False] * (len(ids) - end)
            return tuple(0 if f else 1 for f in flags)
    return (1,) * len(ids)


def _question_end(ids: list, start: int, trie: dict, eos_id: int) -> int | None:
    """Where a whole bank question that starts at `start` ends (after its EOS, or where the template's own end
    of turn follows the finished question), or None when none starts there."""
    node = trie
    for i in range(start, len(ids)):
        if ids[i] not in node:
            return i if eos_id in node else None
        node = node[ids[i]]
        if ids[i] == eos_id:
            return i + 1
    return len(ids) if eos_id in node else None


def action_spans(labels: list, eos_id: int) -> list:
    """(start, end) of each action in a sequence's labels: a run of labelled tokens up to and with its EOS."""
    spans, start = [], None
    for i, t in enumerate(labels):
        if t == IGNORE:
            start = None
            continue
        start = i if start is None else start
        if t == eos_id:
            spans.append((start, i + 1))
            start = None
    return spans


def mask_forced(example: tuple, trie: dict, eos_id: int) -> tuple:
    """`(ids, labels)` with the labels of forced question tokens set to IGNORE (see the module)."""
    ids, labels = example
    labels = list(labels)
    for start, end in action_spans(labels, eos_id):
        for i, f in enumerate(forced(trie, labels[start:end])):
            if f:
                labels[start + i] = IGNORE
    return ids, labels


def mask_examples(examples: list, tokenizer, questions) -> tuple:
    """Every example masked (`mask_forced`) and how many labelled tokens that removed."""
    trie = question_trie(tokenizer, questions)
    out, removed = [], 0
    for ex in examples:
        masked = mask_forced(ex, trie, tokenizer.eos_token_id)
        removed += sum(a != b for a, b in zip(ex[1], masked[1], strict=True))
        out.append(masked)
    return out, removed
