"""The ceiling row: the privileged oracle at the table's own step budget.

A table of model rows at B steps needs its teacher row at B steps too (at 15 steps even the oracle makes no
eggs). When the records hold no oracle (or LLM teacher) episodes, `adapt eval` runs the scripted oracle on
the same (persona, task, scene seed) units at the records' budget, with the offline user, and adds them as
the `oracle` method (`agent_config["computed"]`): a few seconds for hundreds of episodes.
"""

from __future__ import annotations

from .record import EpisodeRecord

TEACHERS = ("oracle", "teacher")


def needs_ceiling(records: list) -> bool:
    """Whether the records lack a teacher row (and have something to compare with it)."""
    return bool(records) and not any(r.agent in TEACHERS for r in records)


def ceiling(records: list, domain) -> tuple:
    """(oracle records at the records' budget on their units, a line saying what was done); ((), line)
    when the records are of another spec or mix budgets."""
    from .batches import run_batched
    from .registry import make
    from .rollout import Job

    budgets = {r.budget for r in records}
    if len(budgets) != 1:
        return (), "no ceiling row: the records mix step budgets"
    if any(r.spec_hash not in (None, domain.spec_hash) for r in records):
        return (), "no ceiling row: the records are of another spec than --spec"
    (budget,) = budgets
    units = sorted({(r.persona, r.task, r.seed) for r in records if r.persona in domain.persona
                    and r.task in domain.task})
    jobs = [Job("oracle", p, t, s) for p, t, s in units]
    from ..runtime.users import OfflineUser

    config = {"agent": "oracle", "user": "offline", "max_steps": budget, "computed": True}
    out = [EpisodeRecord.from_dict(d) for d in run_batched(jobs, domain, make("oracle", domain),
                                                           OfflineUser, 1, config, budget)]
    return tuple(out), (f"teacher row: the oracle computed by `adapt eval` at the same {budget}-step budget on the "
                        f"same {len(out)} (persona, task, scene seed) episodes (--no-ceiling leaves it out)")
