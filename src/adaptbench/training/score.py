"""P(a | x) for Reflection-DPO: the arithmetic mean of the action's per-token probabilities under the
student (a forced forward pass, no grammar mask, the student's own prompt), the end token included,
through the backend's batched `score` (healed like generation: `llm.boundary.score`), in float32.

    probs = step_probabilities(backend, prompt_text, answered_text, teacher_action, student_action,
                               student_ids=decision.stats["token_ids"])

Teacher actions are off-policy text: scored on their canonical tokens and the end token the chat
template closes the turn with. The student's action is on-policy: scored on the ids it generated when
they are given (a grammar-constrained decoder may split the same text differently from the tokenizer).
"""

from __future__ import annotations

from dataclasses import dataclass

SCORE_DTYPE = "float32"  # reference and reflection scores: bfloat16 differs by up to 0.03 batched vs alone


@dataclass(frozen=True)
class StepProbs:
    """The three probabilities of a step: P(a^t | x), P(a^t | x, q, answer), P(a^s | x)."""

    p_teacher: float
    p_teacher_given_answer: float
    p_student: float


def step_probabilities(backend, prompt: str, answered: str, teacher: str, student: str,
                       student_ids=None, dtype: str | None = SCORE_DTYPE) -> StepProbs:
    """Score a step: `prompt` is the student's rendered prompt x (ending with the action prefix),
    `answered` the same prompt after the question and the user's answer; the actions are the texts
    after the prefix, `student_ids` the ids the student generated for its action (then scored instead
    of its text). One batched `score` call per prompt (a^t and a^s share x), in `dtype`."""
    from ..llm.boundary import score

    t, s = score(backend, prompt, [teacher, student if student_ids is None else list(student_ids)], dtype=dtype)
    (ta,) = score(backend, answered, [teacher], dtype=dtype)
    return StepProbs(t.mean_prob, ta.mean_prob, s.mean_prob)
