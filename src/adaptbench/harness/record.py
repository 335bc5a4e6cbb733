"""Run records: the typed, versioned schema of one episode in a results file (one JSON line each).

    rec = EpisodeRecord.from_dict(json.loads(line))   # RecordError (with the reason) when it is not one
    line = rec.to_json()

Version history (`version` field):
- 0: records written before the schema was versioned (no `version` field). Read as they are; the
  agent configuration defaults to the scripted agent with the offline user.
- 1: `version`, the header (agent, agent configuration, persona, task, seed, spec hash, scene), the
  steps (action, ok, observation, reply; a model policy's prompt, completion and token statistics),
  the verdicts (preferences, satisfied, violated, satisfaction rate, questions, completed components),
  `notes` when a scripted agent could not do part of the task, or, for an episode that ended in an
  exception, `error` and `traceback`; `split` for a trained agent's evaluation.
- 2: a question step carries `targets`: the ids of the preferences the question targets, as the
  offline user's matcher decides (what the offline user answered from; the judge of an LLM user's
  questions). Older records have none: their question precision is n/a.
- 3: a sampling model agent's `agent_config` holds `sample_seed` next to `temperature` (part of the
  episode's identity: resume skips an episode only under the same seed and temperature), and a model
  step's `stats` hold `over_budget: true` (and `over_budget_tokens`) when its prompt exceeded the token
  budget even with every older step left out. Older records do not say: `adapt eval` counts them apart.
- 4: every record's `agent_config` holds `max_steps`, the step budget it ran under (scripted agents'
  included; always-ask may take 1 + 1/N times as many steps). Older records without it ran at the
  environment's default, 50 (`EpisodeRecord.budget`).

A record of a newer version than this code knows is refused (`RecordError`), never half-read.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

from ..errors import AdaptError
from ..runtime.env import MAX_STEPS as DEFAULT_BUDGET

RECORD_VERSION = 4
VERDICTS = ("satisfied", "violated", "inapplicable")


class RecordError(AdaptError, ValueError):
    """A JSON object that is not a usable episode record; the message is the reason (for counting)."""


def _number(x) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


@dataclass(frozen=True)
class StepRecord:
    """One step: the action, whether it succeeded, the observation, the user's reply; for model
    policies the prompt, the completion and token statistics (absent for scripted agents); for a
    question, `targets`: the ids of the preferences it targets (None: not recorded, before version 2)."""

    action: str
    ok: bool
    observation: str
    reply: str = ""
    prompt: object = None
    completion: str | None = None
    stats: dict | None = None
    targets: tuple | None = None

    @property
    def is_question(self) -> bool:
        """Whether the step asked the user a question (an `Ask` that succeeded)."""
        return self.ok and self.action.startswith("Ask ")

    def to_dict(self) -> dict:
        """JSON-friendly form (model fields only when present)."""
        out = {"action": self.action, "ok": self.ok, "observation": self.observation, "reply": self.reply}
        if self.prompt is not None:
            out["prompt"] = self.prompt
        if self.completion is not None:
            out["completion"] = self.completion
        if self.stats:
            out["stats"] = self.stats
        if self.targets is not None:
            out["targets"] = list(self.targets)
        return out

    @classmethod
    def from_dict(cls, data) -> StepRecord:
        """Read a step; RecordError when it is malformed."""
        if not isinstance(data, dict) or not isinstance(data.get("action"), str):
            raise RecordError("bad steps")
        targets = data.get("targets")
        if targets is not None and (not isinstance(targets, list | tuple) or not all(isinstance(t, str) for t in targets)):
            raise RecordError("bad steps")
        return cls(data["action"], bool(data.get("ok")), str(data.get("observation", "")),
                   str(data.get("reply") or ""), data.get("prompt"), data.get("completion"), data.get("stats"),
                   None if targets is None else tuple(targets))


@dataclass(frozen=True)
class EpisodeRecord:
    """One episode's record (see the module docstring for the versions)."""

    agent: str
    persona: str
    task: str
    seed: int
    spec_hash: str | None = None
    agent_config: dict = field(default_factory=dict)
    scene: str | None = None
    steps: tuple = ()
    satisfied: int | None = None
    violated: int | None = None
    preferences: tuple = ()  # ({"id", "text", "verdict", "reason", "steps"}, ...)
    satisfaction_rate: float | None = None
    questions: int | None = None
    completed: tuple = ()
    split: int | None = None  # the cross-validation split a trained agent was evaluated on
    notes: tuple = ()  # what a scripted agent could not do on the task ("no recipe for component X")
    error: str | None = None
    traceback: str | None = None
    version: int = RECORD_VERSION

    @property
    def n_steps(self) -> int:
        """Number of steps taken."""
        return len(self.steps)

    @property
    def config(self) -> dict:
        """The agent configuration (version 0 records: the scripted agent with the offline user)."""
        return self.agent_config or {"agent": self.agent, "user": "offline"}

    @property
    def budget(self) -> int:
        """The step budget the episode ran under (records before budgets were recorded ran at the
        environment's default, 50)."""
        return int(self.config.get("max_steps") or DEFAULT_BUDGET)

    @property
    def temperature(self) -> float | None:
        """The model agent's sampling temperature (None: a scripted agent, or not recorded)."""
        return self.config.get("temperature")

    @property
    def sample_seed(self) -> int | None:
        """The sample seed the model agent sampled under (None: greedy, scripted or not recorded)."""
        return self.config.get("sample_seed")

    @property
    def over_budget(self) -> int:
        """Steps whose prompt exceeded the token budget even with every older step left out."""
        return sum(1 for s in self.steps if (s.stats or {}).get("over_budget"))

    def to_dict(self) -> dict:
        """JSON-friendly form (what a results file holds)."""
        out = {"version": self.version, "agent": self.agent, "agent_config": self.agent_config,
               "persona": self.persona, "task": self.task, "seed": self.seed, "spec_hash": self.spec_hash}
        if self.split is not None:
            out["split"] = self.split
        if self.error is not None:
            return {**out, "error": self.error, "traceback": self.traceback}
        return {**out, "scene": self.scene, "steps": [s.to_dict() for s in self.steps], "n_steps": self.n_steps,
                "satisfied": self.satisfied, "violated": self.violated, "preferences": list(self.preferences),
                "satisfaction_rate": self.satisfaction_rate, "questions": self.questions,
                "completed": list(self.completed), **({"notes": list(self.notes)} if self.notes else {})}

    def to_json(self) -> str:
        """One line of a results file (without the newline)."""
        return json.dumps(self.to_dict())

    @classmethod
    def from_json(cls, text: str) -> EpisodeRecord:
        """Read a record from its JSON text; RecordError when it is not one."""
        try:
            data = json.loads(text)
        except json.JSONDecodeError:
            raise RecordError("not JSON") from None
        return cls.from_dict(data)

    @classmethod
    def from_dict(cls, data) -> EpisodeRecord:
        """Read a record of any known version; RecordError (the reason) when it is not a usable one."""
        if not isinstance(data, dict) or not {"agent", "persona", "task", "seed"} <= set(data):
            raise RecordError("not an episode record")
        version = data.get("version", 0)
        if not isinstance(version, int) or isinstance(version, bool) or version < 0:
            raise RecordError("bad version")
        if version > RECORD_VERSION:
            raise RecordError(f"record version {version} is newer than this adaptbench reads ({RECORD_VERSION})")
        if not isinstance(data["agent"], str) or not isinstance(data["persona"], str):
            raise RecordError("bad agent or persona")
        header = {"agent": data["agent"], "persona": data["persona"], "task": data["task"], "seed": data["seed"],
                  "spec_hash": data.get("spec_hash"), "agent_config": data.get("agent_config") or {},
                  "split": _split(data), "version": version}
        if "error" in data:
            return cls(**header, error=str(data["error"]), traceback=data.get("traceback"))
        return cls(**header, **_outcome(data))


def _split(data: dict):
    """The split id as a number (whether the domain has it is checked by `records.load_runs`)."""
    if "split" not in data:
        return None
    split = data["split"]
    if isinstance(split, bool) or not isinstance(split, int | str):
        raise RecordError("unknown split")
    try:
        return int(split)
    except ValueError:
        raise RecordError("unknown split") from None


def _outcome(data: dict) -> dict:
    if "satisfaction_rate" not in data or "questions" not in data:
        raise RecordError("not an episode record")
    rate, q = data["satisfaction_rate"], data["questions"]
    if rate is not None and (not _number(rate) or not 0 <= rate <= 1):
        raise RecordError("bad satisfaction_rate")
    if not _number(q) or q < 0:
        raise RecordError("bad questions")
    steps = data.get("steps") or ()
    prefs = data.get("preferences") or ()
    if not isinstance(steps, list | tuple) or not isinstance(prefs, list | tuple):
        raise RecordError("bad steps")
    return {"scene": data.get("scene"), "steps": tuple(StepRecord.from_dict(s) for s in steps),
            "satisfied": data.get("satisfied"), "violated": data.get("violated"),
            "preferences": tuple(p for p in prefs if isinstance(p, dict) and p.get("verdict") in VERDICTS),
            "satisfaction_rate": rate, "questions": q, "completed": tuple(data.get("completed") or ()),
            "notes": tuple(data.get("notes") or ())}
