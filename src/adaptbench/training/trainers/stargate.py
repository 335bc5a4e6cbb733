"""STaR-GATE's rows: the student's own steps in the top fraction of its rollouts by satisfaction rate.

    records = read_rollouts("runs/student.jsonl", agent="planner")
    kept = top_fraction(records, 1 / 3)
    rows, skipped = stargate_rows(domain, kept, encoder, budget=2000)

Selection: the records of one agent, or of several named with commas (error records left out; a line
that is not a record stops the run, naming its file:line, unless told to skip bad rows), sorted by
satisfaction rate, best first (ties:
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

from pathlib import Path

from ...llm.chat import fit
from ...llm.prompts import PromptBuilder
from ..dataset import bad_rows_error, read_rows, skipped_note
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


def read_rollouts(data, agent: str = "planner", skip_bad: bool = False, log=None) -> list:
    """The episode records of `agent` (one name, or several separated by commas: `oracle,oracle-ask`) in a
    rollout results file or a directory of them (other agents' records and error records left out). A
    line that is not a record (not JSON, not an object, a record of `agent` without the fields a replay
    needs) is a `BadRows` error naming it by file:line, unless `skip_bad`: then it is left out and the
    count reported through `log`."""
    return read_rollouts_counted(data, agent, skip_bad, log)[0]


def read_rollouts_counted(data, agent: str = "planner", skip_bad: bool = False, log=None) -> tuple:
    """(records, bad lines left out) as `read_rollouts` reads them."""
    agents = set(agent_names(agent))
    out, skipped = [], 0
    for f in _files(data):
        rows, bad, torn = read_rows(f, lambda r: _record_problem(r, agents))
        if torn:
            bad.append((len(f.read_bytes().split(b"\n")), "a torn last line (no newline, not a record: a kill "
                        "mid-write; `adapt rollout` with the same --out repairs it)"))
        if bad and not skip_bad:
            raise bad_rows_error(f, bad)
        if bad and log:
            log(skipped_note(f, bad))
        skipped += len(bad)
        out += [r for r in rows if r.get("agent") in agents and "error" not in r
                and r["satisfaction_rate"] is not None]
    if not out:
        raise DataError(f"--data {data}: no finished rollouts of agent '{agent}'")
    return out, skipped


def _record_problem(r, agents: set) -> str | None:
    """What makes a results line unusable: not an object, or a finished record of one of `agents` without
    a replay's fields (persona, task, seed, steps with their actions, satisfaction_rate)."""
    if not isinstance(r, dict):
        return f"a record must be a JSON object (got {type(r).__name__})"
    if r.get("agent") not in agents or "error" in r:
        return None
    for k, kind in (("persona", str), ("task", str), ("seed", int), ("steps", list),
                    ("satisfaction_rate", (int, float, type(None)))):
        if not isinstance(r.get(k), kind) or isinstance(r.get(k), bool) or k not in r:
            return f"a record of agent '{r['agent']}' needs {k} ({getattr(kind, '__name__', 'a number')})"
    if not all(isinstance(s, dict) and isinstance(s.get("action"), str) for s in r["steps"]):
        return "every step of a record needs its action (text)"
    return None


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

