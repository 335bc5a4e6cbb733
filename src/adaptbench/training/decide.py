"""Reflection-DPO's decision rule (Algorithm 1): which completion a step's pair prefers.

    d = decide(p_teacher=0.1, p_teacher_given_answer=0.5, p_student=0.6)   # Decision("question", ...)

Δq = P(a^t | x, q, answer) − P(a^t | x): how much the answer to the question helps predict the teacher's
action. Δt = P(a^s | x) − P(a^t | x): how much more the student believes its own action. Chosen: the
teacher's action a^t when Δt < 0 (the student already leans to it); else the question q when Δq > ε1;
else a^t when Δt < ε2; else the step is skipped (never turned into a supervised target). Rejected: a^s.
"""

from __future__ import annotations

from dataclasses import dataclass

EPS1 = 0.2
EPS2 = 0.5
KINDS = ("question", "teacher", "skipped")


@dataclass(frozen=True)
class Decision:
    """What a step's pair prefers: `kind` (question / teacher / skipped), the skip reason (None unless
    skipped), and Δq, Δt."""

    kind: str
    skip_reason: str | None
    delta_q: float
    delta_t: float


def decide(p_teacher: float, p_teacher_given_answer: float, p_student: float,
           eps1: float = EPS1, eps2: float = EPS2) -> Decision:
    """The decision rule on the three probabilities (see the module docstring)."""
    dq = p_teacher_given_answer - p_teacher
    dt = p_student - p_teacher
    if dt < 0:
        return Decision("teacher", None, dq, dt)
    if dq > eps1:
        return Decision("question", None, dq, dt)
    if dt < eps2:
        return Decision("teacher", None, dq, dt)
    return Decision("skipped", "no_gain", dq, dt)
