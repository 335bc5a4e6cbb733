"""STaR-GATE's rows: the student's own steps in the top fraction of its rollouts by satisfaction rate.

    records = read_rollouts("runs/student.jsonl", agent="planner")
    kept = top_fraction(records, 1 / 3)
    rows, skipped = stargate_rows(domain, kept, encoder, budget=2000)

Selection: the records of one agent, or of several named with commas (error records left out), sorted by satisfaction rate, best first (ties:
more task components completed first, then by persona, task, seed: a weak student leaves most episodes at
0%, and among those the ones that got further are the better examples), the first round(n * top) of them
(at least one). Each kept record is replayed in
the simulator (same scene, the offline user) to rebuild the view the student had at every step; a record
whose replay does not reproduce its observations and replies (another spec version, or an LLM user) is
left out and counted. Each step's prompt is rebuilt as the planner builds it (`LLMPolicy`): the planner
prompt of the view with the dishes made after each earlier step, left-truncated with `chat.fit` (whole oldest
steps) to the rollout's own prompt budget, or to `max_length` less the completion when that is smaller; the
target is the action the student took, then the end token.
"""

from __future__ import annotations

import json
from pathlib import Path

from ...llm.chat import fit
from ...llm.prompts import PromptBuilder
from ..replay import replay
from .encode import Encoded, Encoder
from .rows import DataError


def _files(data) -> list:
    p = Path(data)
    if p.is_dir():
        files = sorted(p.glob("*.jsonl"))
        if not files:
            raise DataError(f"--data {data}: no .jsonl rollout results in the directory")
        return files
    if not p.is_file():
        raise DataError(f"--data {data}: no such file or directory (`adapt rollout --agent planner --model DIR "
                        "--out FILE` writes one)")
    return [p]


def agent_names(agent: str) -> list:
    """The agents `--agent` names: one, or several separated by commas (`oracle,oracle-ask`)."""
    return [a.strip() for a in agent.split(",") if a.strip()]


def read_rollouts(data, agent: str = "planner") -> list:
    """The episode records of `agent` (one name, or several separated by commas: `oracle,oracle-ask`) in a
    rollout results file or a directory of them (error records and unreadable lines left out)."""
    agents = set(agent_names(agent))
    out = []
    for f in _files(data):
        for line in f.read_text(encoding="utf-8").splitlines():
            try:
                r = json.loads(line)
            except ValueError:
                continue
            if isinstance(r, dict) and r.get("agent") in agents and "steps" in r and "error" not in r \
                    and r.get("satisfaction_rate") is not None:
                out.append(r)
    if not out:
        raise DataError(f"--data {data}: no finished rollouts of agent '{agent}'")
    return out


def top_fraction(records: list, top: float) -> list:
    """The best `top` of the records by satisfaction rate (at least one)."""
    order = sorted(records, key=lambda r: (-r["satisfaction_rate"], -len(r.get("completed") or ()), r["persona"],
                                           r["task"], r["seed"]))
    return order[:max(1, round(len(order) * top))]


def step_row(builder, enc: Encoder, key: tuple, view, made_after, action: str, budget) -> Encoded:
    """One step as the planner prompted it, with the student's action as the target."""
    def build(omit: int):
        return builder.prompt(view, omit=omit, preferences=(), unmet=(), force_ask=False, made_after=made_after)

    prompt = fit(enc.tok, build, budget)
    ids, (target,), _ = enc.row(prompt.messages, action)
    return Encoded(key, ids, target, None, prompt.omitted > 0)


def stargate_rows(domain, records: list, enc: Encoder, max_length: int) -> tuple:
    """(rows, records left out because their replay differs): every step of every record."""
    builder = PromptBuilder(domain, "planner")
    rows, unreplayable = [], 0
    for r in records:
        steps = replay(domain, r)
        if steps is None:
            unreplayable += 1
            continue
        own = (r.get("agent_config") or {}).get("budget")
        for i, ((view, made_after), step) in enumerate(zip(steps, r["steps"], strict=True)):
            action = step["action"]
            room = max_length - len(enc.tok(action, add_special_tokens=False)["input_ids"]) - 8
            budget = room if own is None else min(own, room)
            rows.append(step_row(builder, enc, (r["persona"], r["task"], r["seed"], 1, i), view, made_after,
                                 action, budget))
    return rows, unreplayable


def split_of(domain, records: list) -> int | None:
    """The cross-validation split the rollouts train for: the one split whose held-out personas none of
    them plays (a split's training personas only), so that `adapt eval` puts the trained model's episodes
    in that split's seen and unseen columns; None when no split, or more than one, fits."""
    played = {r["persona"] for r in records}
    fits = [sp.id for sp in domain.splits if not played & set(sp.unseen)]
    return fits[0] if len(fits) == 1 else None

