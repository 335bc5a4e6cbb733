"""Rebuild what an agent saw at each step of a recorded episode by replaying its actions in the simulator:
the one replay behind pretraining (`adapt model pretrain`) and STaR-GATE's rows."""

from __future__ import annotations


def replay(domain, record):
    """(view, made_after) before each step of a record, rebuilt in the simulator; None when the replay's
    observations or replies differ from the record's."""
    from ..harness.episode import Episode
    from ..harness.policy import Decision
    from ..runtime.env import make_env

    env = make_env(domain, record["persona"], record["task"], record["seed"])
    ep = Episode(f"{record['agent']}/{record['persona']}/{record['task']}/{record['seed']}", env)  # the rollout's id
    out, made_after = [], []
    for step in record["steps"]:
        out.append((ep.view(), tuple(made_after)))
        turn = ep.apply(Decision(step["action"]))
        if turn.observation != step["observation"] or (turn.reply or "") != (step.get("reply") or ""):
            return None
        made_after.append(ep.view().made)
    return out
