"""P(a | x) for Reflection-DPO: the arithmetic mean of the action text's per-token probabilities under the
student (a forced forward pass, no grammar mask, the student's own prompt), through the backend's batched
`score`.

    probs = step_probabilities(backend, prompt_text, answered_text, teacher_action, student_action)
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class StepProbs:
    """The three probabilities of a step: P(a^t | x), P(a^t | x, q, answer), P(a^s | x)."""

    p_teacher: float
    p_teacher_given_answer: float
    p_student: float


def step_probabilities(backend, prompt: str, answered: str, teacher: str, student: str) -> StepProbs:
    """Score a step: `prompt` is the student's rendered prompt x (ending with the action prefix),
    `answered` the same prompt after the question and the user's answer; the actions are the texts
    after the prefix. One batched `score` call per prompt (a^t and a^s share x)."""
    t, s = backend.score(prompt, [teacher, student])
    (ta,) = backend.score(answered, [teacher])
    return StepProbs(t.mean_prob, ta.mean_prob, s.mean_prob)
