"""The prior-knowledge summary between two interactions (`adapt train data --interactions 2`).

The paper's data collection runs, per persona and task, a first interaction, then a second with "a summary
of the first as prior knowledge" in the planner prompt's prior-knowledge line (where a first interaction
reads "You have no prior information about the user."). The paper prints no prompt for that summary, so it
is built here without a model, from what the student learnt: each question it asked in the first interaction
and the user's answer, in order, repeated questions once. An interaction with no answered question teaches
nothing, and the second interaction then starts with the same line as the first.

    text = prior_summary(first_episode.view())     # "" when nothing was learnt
"""

from __future__ import annotations

from .relabel import question_text

HEADER = "From an earlier breakfast with {user} ({task}), you know what {user} told you:"


def learnt(history) -> list:
    """(question, answer) for every question of a history the user answered, first asking only."""
    out, seen = [], set()
    for turn in history:
        q = question_text(turn.action)
        if q is None or not turn.reply.strip() or q.strip().lower() in seen:
            continue
        seen.add(q.strip().lower())
        out.append((q.strip(), turn.reply.strip()))
    return out


def prior_summary(view, user: str = "the user") -> str:
    """The prior-knowledge text for the next interaction after the episode seen in `view` ("" if the user
    answered nothing: the prompt then says there is no prior information)."""
    pairs = learnt(view.history)
    if not pairs:
        return ""
    task = view.task_text.rstrip(".").lower()
    lines = [HEADER.format(user=user, task=task)]
    lines += [f'- You asked "{q}"; {user} answered: {a}' for q, a in pairs]
    lines.append("Use this where it applies, and ask about what it does not cover.")
    return "\n".join(lines)
