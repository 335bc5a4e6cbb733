"""P(a | x) for Reflection-DPO: the arithmetic mean of the action's per-token probabilities under the
student (a forced forward pass, no grammar mask, the student's own prompt), the end token included,
through the backend's scoring primitive `score_ids` (healed like generation: `llm.boundary.score_group`),
in float32 (a served engine: in its own precision, `--dtype float32` for vLLM).

    probs = step_probabilities(backend, prompt_text, answered_text, teacher_action, student_action,
                               student_ids=decision.stats["token_ids"])
    many = steps_probabilities(backend, [Step(prompt_text, answered_text, a_t, a_s, ids), ...])

The same ids are scored whichever backend reads them: the local model (`hf.TransformersBackend`, x read
once for a^t and a^s) or a served one (`openai_backend.OpenAIBackend`: the server's prompt
log-probabilities, every step of a batch's requests in flight at once).

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


@dataclass(frozen=True)
class Step:
    """What a step scores: the student's rendered prompt x (ending with the action prefix), the same
    prompt after the question and the user's answer, the teacher's and the student's actions (the texts
    after the prefix), and the ids the student generated for its action (None: its text is scored)."""

    prompt: str
    answered: str
    teacher: str
    student: str
    student_ids: tuple | None = None


def step_probabilities(backend, prompt: str, answered: str, teacher: str, student: str,
                       student_ids=None, dtype: str | None = SCORE_DTYPE) -> StepProbs:
    """Score a step: `prompt` is the student's rendered prompt x (ending with the action prefix),
    `answered` the same prompt after the question and the user's answer; the actions are the texts
    after the prefix, `student_ids` the ids the student generated for its action (then scored instead
    of its text). In `dtype`."""
    return steps_probabilities(backend, [Step(prompt, answered, teacher, student, student_ids)], dtype)[0]


def steps_probabilities(backend, steps, dtype: str | None = SCORE_DTYPE) -> list:
    """`StepProbs` of every `Step` from one `score_ids` call (a served backend sends them all at once):
    per step two groups, x with [a^t, a^s] (one reading of x) and (x, q, answer) with [a^t], healed
    like `boundary.score`."""
    from ..llm.backend import mean_prob
    from ..llm.boundary import score_group

    groups = []
    for s in steps:
        groups.append(score_group(backend, s.prompt, [s.teacher, s.student if s.student_ids is None
                                                      else list(s.student_ids)]))
        groups.append(score_group(backend, s.answered, [s.teacher]))
    got = backend.score_ids(groups, dtype=dtype) if groups else []
    return [StepProbs(mean_prob(t), mean_prob(ta), mean_prob(sa))
            for (t, sa), (ta,) in zip(got[0::2], got[1::2], strict=True)]
