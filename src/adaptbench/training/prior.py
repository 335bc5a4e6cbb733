"""The prior-knowledge summary between two interactions (`adapt train data --interactions 2`).

The paper's data collection runs, per persona and task, a first interaction, then a second with "a summary
of the first as prior knowledge" in the planner prompt's prior-knowledge line (where a first interaction
reads "You have no prior information about the user."). The paper prints no prompt for that summary, so it
is built here without a model from what the student learnt: each question it asked in the first interaction
that the user answered from a preference (the step's `targets`, as the offline user's matcher finds them;
"I'm not sure where things are kept" teaches nothing), with the answer, in order, a repeated question once.
An interaction that learnt nothing leaves the second with the same line as the first.

    text = prior_summary(first_episode)     # "" when nothing was learnt
"""

from __future__ import annotations

from .relabel import question_text

HEADER = "From an earlier breakfast with {user} ({task}), you know what {user} told you:"


def learnt(steps) -> list:
    """(question, answer, preference ids) for every question of the step records that the user answered
    from a preference, the first asking only."""
    out, seen = [], set()
    for step in steps:
        q = question_text(step.action)
        if q is None or not step.ok or not step.reply.strip() or not step.targets:
            continue
        if q.strip().lower() in seen:
            continue
        seen.add(q.strip().lower())
        out.append((q.strip(), step.reply.strip(), tuple(step.targets)))
    return out


def prior_summary(episode, user: str = "the user") -> str:
    """The prior-knowledge text for the next interaction after `episode` (a `harness.episode.Episode`):
    "" if the user told it no preference (the prompt then says there is no prior information)."""
    pairs = learnt(episode.steps)
    if not pairs:
        return ""
    task = episode.env.task.text.rstrip(".").lower()
    lines = [HEADER.format(user=user, task=task)]
    lines += [f'- You asked "{q}"; {user} answered: {a}' for q, a, _ in pairs]
    lines.append("Use this where it applies, and ask about what it does not cover.")
    return "\n".join(lines)
