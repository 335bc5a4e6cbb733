"""Answer-following rows: the answer-use probe's prompt pairs as training steps, built in training scenes
from training personas only (`adapt model student --pair-seeds`).

    rows = answer_rows(domain, personas, seeds=range(100, 112))      # both sides of every pair
    write_rows(path, rows); data = answer_examples(read_rows([path]), tokenizer)

A pair (`llm.probe`) is two planner prompts that differ only in the user's answer to one recipe question,
at the first step where the two answers' plans act differently; each side's row is its prompt and the
action its answer's plan takes. Trained on both sides, the only thing that tells the two targets apart
is the answer: the signal a student trained on whole oracle episodes gets too rarely to learn (one
answer-dependent action among ~30 per episode, and in the plain oracle's episodes the same actions come
with no answer at all). Both placements of the question are used (just before the recipe, and as the
first action). A pair is kept only when both of its answers are training personas' preferences, so an
unseen persona's words never reach the data; the probe's own scenes (seed 0 by default) stay apart.
"""

from __future__ import annotations

import json
from pathlib import Path

KIND = "answer"  # the `kind` of a row in a data file (episode records have `steps` instead)
# What of a row's prompt is trained on: "full", the planner prompt the student acts on; "dialogue", the
# messages from the user turn before the question onward (task, question, reply and what followed; no system
# message, no layout): ~3x fewer tokens, the same distance from the reply to the action (bench/answer_context.py)
CONTEXTS = ("full", "dialogue")


def answer_rows(domain, personas, seeds, places=("recipe", "start"), tasks=None) -> list:
    """Both sides of every probe pair whose answers are both from `personas`, in the scenes of `seeds`
    (of `tasks`; None: all), for each placement of the question: dicts with the pair's key, the
    placement, the prompt's messages and prefix, and the side's action."""
    from ..llm.probe import build_pairs

    keep, rows = set(personas), []
    for at in places:
        for pair in build_pairs(domain, tasks=tasks, personas=sorted(keep), seeds=tuple(seeds), at=at):
            if pair.a.persona not in keep or pair.b.persona not in keep:
                continue
            rows += _rows(pair, at)
    return rows


def said_rows(domain, seeds, places=("recipe", "start"), tasks=None) -> list:
    """Both sides of every templated-reply pair (`llm.probe.said_pairs`: every option of every asked choice
    named in a plain reply, no persona's words) in the scenes of `seeds`, for each placement."""
    from ..llm.probe import said_pairs

    return [row for at in places for pair in said_pairs(domain, tasks=tasks, seeds=tuple(seeds), at=at)
            for row in _rows(pair, at)]


def _rows(pair, at: str) -> list:
    return [{"kind": KIND, "key": pair.key(), "at": at, "messages": list(side.prompt.messages),
             "prefix": side.prompt.prefix, "action": side.action} for side in (pair.a, pair.b)]


def write_rows(path, rows: list) -> None:
    """Write rows as JSON lines (through a temporary file: a killed write leaves no half file)."""
    path = Path(path)
    tmp = path.with_suffix(".tmp")
    tmp.write_text("".join(json.dumps(r) + "\n" for r in rows))
    tmp.replace(path)


def read_rows(paths) -> list:
    """The answer rows in data files (other lines, such as episode records, skipped)."""
    from .pretrain import json_objects

    return [r for r in json_objects(paths) if r.get("kind") == KIND]


def dialogue(messages: list) -> list:
    """A row's messages cut to its dialogue: from the user turn before the first question onward, without
    the system message (the last three messages when nothing was asked)."""
    asks = [i for i, m in enumerate(messages) if m["role"] == "assistant" and m["content"].startswith("Action: Ask")]
    start = max(asks[0] - 1, 0) if asks else max(len(messages) - 3, 0)
    return [m for m in messages[start:] if m["role"] != "system"]


def answer_examples(rows: list, tokenizer, context: str = "full") -> list:
    """Training sequences `(ids, labels)`: each row's rendered prompt (all of it, or with `context`
    "dialogue" its `dialogue`) with no loss, then its action and EOS."""
    from ..llm.chat import render
    from ..llm.prompts import Prompt
    from .pretrain import IGNORE

    if context not in CONTEXTS:
        raise ValueError(f"unknown row context '{context}' (choose from: {', '.join(CONTEXTS)})")
    out = []
    for r in rows:
        messages = r["messages"] if context == "full" else dialogue(list(r["messages"]))
        prompt = Prompt(tuple(messages), r.get("prefix", ""))
        p = tokenizer(render(tokenizer, prompt), add_special_tokens=False)["input_ids"]
        t = tokenizer(r["action"], add_special_tokens=False)["input_ids"] + [tokenizer.eos_token_id]
        out.append((p + t, [IGNORE] * len(p) + t))
    return out
