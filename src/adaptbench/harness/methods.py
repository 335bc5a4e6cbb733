"""Which method an episode record belongs to, the rows of the paper's Table 1 and Table 2, and the
numbers the paper published for them (`adapt eval --paper`).

A record's METHOD (the label its row shows) is, first match wins:
1. `--method NAME[@SPLIT]=FILE`: every record read from FILE is method NAME (evaluated on SPLIT);
2. `agent_config["method"]`, when the rollout recorded one;
3. the training provenance of the model the record's agent ran (`agent_config["model"]`, a directory,
   as given to the rollout or relative to the results file's folder): `training.json` in it
   (`{"method": "dpo", "split": 1}`, any trainer may write one), else `adapt train`'s output layout,
   where the model is OUT/merged: OUT/train.json's `method`, and the split from OUT/train.json, else
   OUT/settings.json, else the first pair of the training data (`settings["data"]/pairs.jsonl`); a base
   student's `student.json` gives only its split (its rows stay the agent's: `planner` is the baseline);
4. the agent's name (`planner`, `react`, `oracle`, ...).
Training method names are normalised (`dpo` -> `reflection-dpo`, `sft` -> `no-dpo`, `stargate` ->
`star-gate`, ...). A record without its own `split` takes the one given in 1 or found in 3.

A paper row is filled by the first of its candidate methods that has records: "never-ask" by the
LLM `never-ask-llm`, else the scripted `never-ask`; "baseline" by `planner` (the untrained model);
"teacher" by the LLM `teacher`, else the scripted `oracle`; trained rows by their training method.
A row no method fills is shown as missing; methods no row takes are listed below the tables.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

PROVENANCE = "training.json"  # in a trained model's directory: {"method": ..., "split": ..., ...}
STUDENT_PROVENANCE = "student.json"  # a base student's (`adapt model student`, `adapt model curve`): its split
TRAIN_OUTPUTS = ("merged", "adapter")  # the model folders of `adapt train`'s OUT, beside OUT/train.json

ALIASES = {"dpo": "reflection-dpo", "reflection_dpo": "reflection-dpo", "reflection-dpo": "reflection-dpo",
           "sft": "no-dpo", "no_dpo": "no-dpo", "no-dpo": "no-dpo", "star-gate": "star-gate",
           "star_gate": "star-gate", "stargate": "star-gate", "no-reflection": "no-reflection",
           "no_reflection": "no-reflection"}


@dataclass(frozen=True)
class PaperRow:
    """A row of the paper's tables: its id, the paper's label, the methods that may fill it (first with
    records wins) and the published numbers: satisfaction seen/unseen and questions seen/unseen, each
    (mean, standard error), percentages for satisfaction."""

    id: str
    label: str
    candidates: tuple
    paper: tuple


TABLE1 = (
    PaperRow("never-ask", "'Never Ask' LLM", ("never-ask-llm", "never-ask"), ((27.5, 0.7), (28.6, 1.2), (0.0, 0.0), (0.0, 0.0))),
    PaperRow("baseline", "Baseline LLM", ("planner",), ((34.7, 0.8), (34.3, 1.3), (2.3, 0.0), (2.3, 0.1))),
    PaperRow("react", "ReAct", ("react",), ((36.1, 0.8), (36.8, 1.4), (2.3, 0.0), (2.4, 0.1))),
    PaperRow("star-gate", "STaR-GATE", ("star-gate",), ((34.1, 0.8), (33.5, 1.4), (2.0, 0.0), (2.0, 0.0))),
    PaperRow("reflection-dpo", "Reflection-DPO", ("reflection-dpo",), ((44.1, 1.0), (42.9, 1.6), (9.8, 0.1), (9.5, 0.2))),
    PaperRow("always-ask", "'Always Ask' LLM", ("always-ask-llm", "always-ask"), ((52.1, 0.9), (50.8, 1.6), (22.2, 0.1), (22.4, 0.2))),
    PaperRow("teacher", "Teacher LLM", ("teacher", "oracle"), ((65.5, 1.1), (65.5, 1.9), (0.0, 0.0), (0.0, 0.0))),
)
TABLE2 = (
    TABLE1[4],
    PaperRow("no-reflection", "Ablation: no Reflection", ("no-reflection",), ((17.5, 0.7), (16.5, 1.2), (1.0, 0.0), (0.9, 0.0))),
    PaperRow("no-dpo", "Ablation: no DPO", ("no-dpo",), ((35.3, 0.8), (34.9, 1.4), (2.9, 0.1), (2.9, 0.1))),
)
TABLES = (("Table 1", TABLE1), ("Table 2", TABLE2))


class MethodError(ValueError):
    """A bad `--method` mapping or provenance file; the message says which."""


def method_name(text: str) -> str:
    """A method name with the training aliases normalised (`dpo` -> `reflection-dpo`)."""
    return ALIASES.get(text.strip().lower(), text.strip())


def parse_mapping(items: list) -> dict:
    """`NAME[@SPLIT]=FILE` items -> {FILE (resolved path): (method, split or None)}; MethodError on a
    malformed one."""
    out = {}
    for item in items or ():
        name, sep, path = item.partition("=")
        name, _, split = name.partition("@")
        if not sep or not name.strip() or not path.strip():
            raise MethodError(f"--method '{item}' is not NAME=FILE or NAME@SPLIT=FILE")
        if split and not split.strip().isdigit():
            raise MethodError(f"--method '{item}': the split must be a number")
        out[str(Path(path.strip()).resolve())] = (method_name(name), int(split) if split else None)
    return out


def _json(path: Path):
    """The JSON object in `path`; MethodError when it is unreadable or not an object."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise MethodError(f"cannot read {path} ({exc})") from None
    if not isinstance(data, dict):
        raise MethodError(f"{path} is not a JSON object")
    return data


def _first_split(data_dir) -> int | None:
    """The `split` of the first training pair in DATA/pairs.jsonl (every pair of a run has the same)."""
    path = Path(str(data_dir)) / "pairs.jsonl"
    try:
        with path.open(encoding="utf-8") as f:
            first = json.loads(f.readline() or "{}")
    except (OSError, ValueError):
        return None
    return first.get("split") if isinstance(first, dict) else None


def _adapt_train(out: Path) -> dict:
    """The provenance of `adapt train`'s OUT (the model being OUT/merged): method and split."""
    run = _json(out / "train.json")
    split = run.get("split")
    if split is None and (out / "settings.json").is_file():
        settings = _json(out / "settings.json")
        split = settings.get("split")
        if split is None and settings.get("data"):
            split = _first_split(settings["data"])
    return {**run, "split": split}


def read_provenance(model: str, bases: tuple = ()) -> dict:
    """The training provenance of a model directory (see the module doc), looked up as given and relative
    to `bases` (e.g. the results file's folder); {} when there is none. MethodError when unreadable."""
    for base in (Path("."), *map(Path, bases)):
        path = base / model
        if (path / PROVENANCE).is_file():
            return _json(path / PROVENANCE)
        if path.name in TRAIN_OUTPUTS and path.is_dir() and (path.parent / "train.json").is_file():
            return _adapt_train(path.parent)
        if (path / STUDENT_PROVENANCE).is_file():  # a base student: trained on a split, no method of its own
            info = _json(path / STUDENT_PROVENANCE)
            return {k: info[k] for k in ("split", "scene_seeds") if info.get(k) is not None}
    return {}


def trained_seeds(model: str, bases: tuple = ()) -> tuple:
    """The scene seeds a model directory was trained on, as its provenance records them (`scene_seeds` of
    training.json / train.json, or of `adapt model student`'s student.json, whose older form lists
    `ask_seeds` and `oracle_seeds`); () when it records none."""
    if not isinstance(model, str) or not model:
        return ()
    seeds = read_provenance(model, bases).get("scene_seeds")
    if seeds is None:
        for base in (Path("."), *map(Path, bases)):
            path = base / model / STUDENT_PROVENANCE
            if path.is_file():
                info = _json(path)
                settings = info.get("settings") or {}
                seeds = info.get("scene_seeds") or [*settings.get("ask_seeds", ()), *settings.get("oracle_seeds", ())]
                break
    return tuple(sorted({int(x) for x in seeds or () if isinstance(x, int) and not isinstance(x, bool)}))


class Resolver:
    """Resolves records to their method (see the module doc), reading each provenance file once."""

    def __init__(self, mapping: dict | None = None):
        self.mapping = mapping or {}
        self._provenance: dict = {}

    def provenance(self, model, base: str) -> dict:
        """The provenance of `model` (cached)."""
        if not isinstance(model, str) or not model:
            return {}
        key = (model, base)
        if key not in self._provenance:
            self._provenance[key] = read_provenance(model, (base,))
        return self._provenance[key]

    def resolve(self, record, source: str | None = None):
        """The record relabelled: `agent` = its method, `split` filled in where known."""
        method, split = self.mapping.get(str(Path(source).resolve()), (None, None)) if source else (None, None)
        config = record.agent_config or {}
        if method is None and isinstance(config.get("method"), str):
            method = method_name(config["method"])
        prov = self.provenance(config.get("model"), str(Path(source).parent) if source else ".")
        if method is None and isinstance(prov.get("method"), str):
            method = method_name(prov["method"])
        if split is None:
            split = _as_split(prov.get("split"))
        changes = {}
        if method is not None and method != record.agent:
            changes["agent"] = method
        if record.split is None and split is not None:
            changes["split"] = split
        return replace(record, **changes) if changes else record


def _as_split(value) -> int | None:
    """A split id from provenance (a number, or its text as `adapt train data --split` takes it), else None."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int):
        return value
    return int(value) if isinstance(value, str) and value.strip().isdigit() else None


def fill(rows_by_method: dict, table: tuple) -> list:
    """(PaperRow, the method filling it or None) for each row of `table`, given the methods with rows."""
    out = []
    for row in table:
        method = next((m for m in row.candidates if m in rows_by_method), None)
        out.append((row, method))
    return out


def others(rows_by_method: dict) -> list:
    """Methods with records that fill no paper row (in the order given)."""
    used = {m for _, table in TABLES for row, m in fill(rows_by_method, table) if m is not None}
    return [m for m in rows_by_method if m not in used]


def mixed_models(records: list) -> list:
    """A line for each (method, split) whose records come from more than one model or agent: a method's
    row should be one model per split (a trained model whose provenance was not found would otherwise
    pass for its base model)."""
    seen: dict = {}
    for r in records:
        config = r.agent_config or {}
        source = f"{config.get('agent', r.agent)}" + (f" {config['model']}" if config.get("model") else "")
        seen.setdefault((r.agent, r.split), set()).add(source)
    return [f"{method}{'' if split is None else f' (split {split})'} mixes {len(s)} agents/models: "
            f"{', '.join(sorted(s))}" for (method, split), s in seen.items() if len(s) > 1]
