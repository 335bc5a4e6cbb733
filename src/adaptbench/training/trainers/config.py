"""One frozen settings dataclass per training method, read from `--config FILE.yaml` and/or flags.

    s = load_settings(DPOSettings, flags={"lr": 2e-4}, path="dpo.yaml")   # defaults < file < flags
    add_arguments(parser, DPOSettings)                                      # --data, --model, ... --beta

Every field carries its help text, type and choices in its metadata (`setting(...)`); the flags are built
from the fields (`max_steps` -> `--max-steps`, booleans -> `--x/--no-x`), default to "not given" so that a
flag given on the command line overrides the file, and a file's keys are checked (an unknown key or a bad
value is a usage error naming it). Needs no torch: the settings are validated before anything heavy loads.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

from ...errors import AdaptError

LAYOUTS = ("chat", "generation")  # TRL's conversational row layout, or the one the model plays in (`--layout`)

LOSSES = ("sigmoid", "ipo", "sigmoid_norm", "sigmoid+sft")
RELEASE_TARGETS = "q_proj,v_proj"


def setting(default, help: str, type=str, choices=None, required: bool = False):  # noqa: A002 - argparse's word
    """A dataclass field with its command-line help, value type and choices."""
    return field(default=default, metadata={"help": help, "type": type, "choices": choices, "required": required})


class SettingsError(AdaptError):
    """A bad setting (file or flag): a usage error."""

    exit_code = 2


@dataclass(frozen=True)
class TrainSettings:
    """What every method shares: where the data, model and output are, steps, batch, learning rate, the
    row length limit and the LoRA adapter."""

    data: str = setting(None, "input: the `adapt train data` output directory (star-gate: `adapt rollout` "
                              "results, a JSONL file or a directory of them)", required=True)
    model: str = setting(None, "the student's model directory (save_pretrained)", required=True)
    out: str = setting(None, "output directory: checkpoints/, adapter/, merged/, log.jsonl, train.json; "
                             "running again with the same --out resumes", required=True)
    max_steps: int = setting(None, "optimizer steps (default: --epochs passes over the rows)", int)
    epochs: float = setting(1.0, "passes over the rows when --max-steps is not given (default 1)", float)
    batch: int = setting(4, "rows per device per step (default 4)", int)
    grad_accum: int = setting(1, "gradient accumulation steps (default 1)", int)
    lr: float = setting(1e-4, "learning rate (default 1e-4, the release's)", float)
    max_length: int = setting(8192, "tokens of prompt plus the longer completion per row; every row is checked "
                                    "and none is cut or dropped silently (default 8192, as `adapt train data`)", int)
    long_rows: str = setting("refuse", "rows longer than --max-length: refuse (exit 1, listing them) or skip "
                                       "(leave them out, listed in OUT/long_rows.jsonl and counted)", str,
                             ("refuse", "skip"))
    lora_r: int = setting(4, "LoRA rank (default 4, the paper's)", int)
    lora_alpha: int = setting(16, "LoRA alpha (default 16, the release's)", int)
    lora_dropout: float = setting(0.01, "LoRA dropout (default 0.01, the release's)", float)
    lora_targets: str = setting(RELEASE_TARGETS, "modules the adapter wraps: comma-separated names (default "
                                                 "q_proj,v_proj as in the release) or all-linear", str)
    save_steps: int = setting(50, "checkpoint every N steps (the last two are kept; default 50)", int)
    logging_steps: int = setting(5, "log a line (loss, rewards) every N steps (default 5)", int)
    seed: int = setting(0, "training seed: shuffling and adapter initialisation (default 0)", int)
    precision: str = setting("auto", "auto (bfloat16 on a GPU that has it, else float32), float32 or bfloat16",
                             str, ("auto", "float32", "bfloat16"))
    gradient_checkpointing: bool = setting(False, "recompute activations in the backward pass (less memory)", bool)
    threads: int = setting(None, "CPU threads for torch (default: torch's)", int)
    allow_eval_seeds: bool = setting(False, "train on data from the evaluation scene seeds 0-3 (refused by default)",
                                     bool)
    skip_bad_rows: bool = setting(False, "leave out the --data lines that are not usable rows (counted, reported "
                                         "and recorded in train.json) instead of stopping at the first (exit 2, "
                                         "naming its file:line)", bool)
    anchor: str = setting(None, "a teacher's episodes trained beside the rows (adapt rollout records: JSONL files or "
                                "directories, comma-separated; e.g. oracle-ask on training personas and scenes): each "
                                "update adds --anchor-weight x the mean token loss of --anchor-per-update whole "
                                "episodes, the loss on every action, so that longer training keeps the recipes "
                                "(default: none, the paper's rows alone)")
    anchor_per_update: int = setting(1, "anchor episodes per forward (default 1)", int)
    anchor_weight: float = setting(1.0, "weight of the anchor episodes' loss (default 1.0)", float)
    dedupe_corrections: bool = setting(False, "keep only each episode's first row that chooses a given action "
                                              "(instance numbers aside): a student that ignores a correction is given "
                                              "it again at every later step, against its own other steps (default off: "
                                              "the paper's Algorithm 1 keeps every step's row)", bool)
    mask_forced: bool = setting(False, "no loss on the tokens of a bank question that the bank forces (after `Ask` "
                                       "and the tokens where two of the domain's questions part): under "
                                       "`--question-set bank` decoding they have probability 1, and a student that "
                                       "never asked spends ~200 nats a question on them, nearly all of a question "
                                       "row's gradient (default off: the paper scores whole completions)", bool)
    layout: str = setting("chat", "how a row is laid out: chat (TRL's conversational layout: the completion is the "
                                  "whole assistant turn, `Action: ` and the end of turn included; default) or "
                                  "generation (the prompt ends with `Action: ` as when the model plays, the completion "
                                  "is the action and the end token: for a student that never writes the prefix)",
                          str, LAYOUTS)

    def check(self) -> None:
        """SettingsError on a value out of range."""
        for name in ("batch", "grad_accum", "max_length", "lora_r", "lora_alpha", "save_steps", "logging_steps"):
            if getattr(self, name) < 1:
                raise SettingsError(f"{flag(name)} must be at least 1 (got {getattr(self, name)})")
        if self.max_steps is not None and self.max_steps < 1:
            raise SettingsError(f"--max-steps must be at least 1 (got {self.max_steps})")
        if self.lr <= 0 or self.epochs <= 0:
            raise SettingsError("--lr and --epochs must be positive")
        if self.anchor_per_update < 1 or self.anchor_weight < 0:
            raise SettingsError("--anchor-per-update must be at least 1 and --anchor-weight not negative")
        if not 0 <= self.lora_dropout < 1:
            raise SettingsError(f"--lora-dropout must be in [0, 1) (got {self.lora_dropout})")

    def targets(self):
        """The LoRA target modules as peft takes them ("all-linear" or a list of names)."""
        t = self.lora_targets.strip()
        return t if t == "all-linear" else [x.strip() for x in t.split(",") if x.strip()]


@dataclass(frozen=True)
class SFTSettings(TrainSettings):
    """`adapt train sft` (the paper's "no DPO" ablation): supervised fine-tuning on the chosen completions of
    the trainable rows (questions and teacher actions), loss on the completion only."""


@dataclass(frozen=True)
class DPOSettings(TrainSettings):
    """`adapt train dpo` (Reflection-DPO): chosen (a question or a^t) against rejected (a^s), LoRA with the
    reference being the adapter switched off."""

    beta: float = setting(0.1, "DPO beta (default 0.1)", float)
    loss: str = setting("sigmoid", "DPO loss: sigmoid (DPO), ipo, sigmoid_norm (sigmoid on the per-token "
                                   "mean log-ratios: length-normalised), or sigmoid+sft (DPO plus the chosen "
                                   "completion's negative log-likelihood, weight 1: RPO); all TRL loss types",
                        str, LOSSES)
    precompute_ref: str = setting("auto", "precompute the reference log-probs in one pass before training: "
                                          "yes, no, or auto (yes when the run sees every row at least once, "
                                          "where it saves a forward pass per step)", str, ("auto", "yes", "no"))

    def check(self) -> None:
        """SettingsError on a value out of range."""
        super().check()
        if self.beta <= 0:
            raise SettingsError(f"--beta must be positive (got {self.beta})")


@dataclass(frozen=True)
class NoReflectionSettings(DPOSettings):
    """`adapt train no-reflection` (Table 2's "no Reflection" ablation): DPO on teacher actions only. Every
    step of pairs.jsonl that reached the decision rule (student and teacher differ, not after two failures)
    becomes chosen a^t, rejected a^s; no question is ever chosen."""

    no_gain: bool = setting(True, "also train on the steps the decision rule skipped as no_gain (Δt >= ε2 with "
                                  "no useful question): without reflection nothing tells them apart (default on)",
                            bool)


@dataclass(frozen=True)
class StarGateSettings(TrainSettings):
    """`adapt train star-gate` (STaR-GATE): supervised fine-tuning on the student's own actions in the top
    fraction of its rollouts by satisfaction rate, each step's prompt rebuilt as the planner renders it."""

    top: float = setting(1 / 3, "fraction of rollouts kept, best satisfaction rate first (default 1/3)", float)
    agent: str = setting("planner", "the rollouts' agent whose records are read (default planner); several "
                         "separated by commas (oracle,oracle-ask: a teacher's trajectories, recorded as method teacher-sft, "
                         "not star-gate)", str)

    def check(self) -> None:
        """SettingsError on a value out of range."""
        super().check()
        if not 0 < self.top <= 1:
            raise SettingsError(f"--top must be in (0, 1] (got {self.top})")
        if self.dedupe_corrections:
            raise SettingsError("--dedupe-corrections applies to pairs (dpo, sft, no-reflection); star-gate trains on "
                                "rollouts, which hold no corrections")


def flag(name: str) -> str:
    """The command-line flag of a field."""
    return "--" + name.replace("_", "-")


def _convert(f, value, where: str):
    kind, choices = f.metadata["type"], f.metadata["choices"]
    if value is None:
        return None
    try:
        if kind is bool:
            if not isinstance(value, bool):
                raise ValueError
            out = value
        elif kind is int:
            if isinstance(value, bool) or (isinstance(value, float) and not value.is_integer()):
                raise ValueError
            out = int(value)
        else:
            out = kind(value)
    except (TypeError, ValueError):
        raise SettingsError(f"{where}: '{value}' is not a valid {f.name} ({kind.__name__})") from None
    if choices and out not in choices:
        raise SettingsError(f"{where}: {f.name} must be one of {', '.join(choices)} (got '{out}')")
    return out


def read_file(path) -> dict:
    """The settings in a YAML file (a mapping; keys with - or _)."""
    import yaml

    p = Path(path)
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SettingsError(f"--config {path}: {exc.strerror or exc}") from None
    except yaml.YAMLError as exc:
        raise SettingsError(f"--config {path}: not YAML ({' '.join(str(exc).split())[:200]})") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise SettingsError(f"--config {path}: expected a mapping of settings, got {type(data).__name__}")
    return {str(k).replace("-", "_"): v for k, v in data.items()}


def load_settings(cls, flags: dict | None = None, path=None):
    """The settings: the class's defaults, overridden by the file's keys, overridden by `flags` (only the
    flags given). SettingsError names an unknown key, a bad value or a missing required setting."""
    known = {f.name: f for f in fields(cls)}
    values = {}
    for source, given in ((f"--config {path}", read_file(path) if path else {}), ("flag", flags or {})):
        unknown = sorted(set(given) - set(known))
        if unknown:
            raise SettingsError(f"{source}: unknown setting {', '.join(unknown)} (known: {', '.join(known)})")
        values.update({k: _convert(known[k], v, source) for k, v in given.items()})
    missing = [flag(f.name) for f in known.values() if f.metadata["required"] and values.get(f.name) is None]
    if missing:
        raise SettingsError(f"missing {', '.join(missing)} (as flags or in --config)")
    s = replace(cls(), **values)
    s.check()
    return s


def add_arguments(parser, cls) -> None:
    """One flag per field of `cls` (help from the field, default: not given) plus `--config`."""
    parser.add_argument("--config", metavar="FILE.yaml", help="settings file (keys as the flags' names without "
                        "--; flags given on the command line override it)")
    for f in fields(cls):
        kw = {"dest": f.name, "default": argparse.SUPPRESS, "help": f.metadata["help"]}
        if f.metadata["type"] is bool:
            parser.add_argument(flag(f.name), action=argparse.BooleanOptionalAction, **kw)
            continue
        if f.metadata["choices"]:
            kw["choices"] = f.metadata["choices"]
        parser.add_argument(flag(f.name), type=f.metadata["type"], **kw)


def given_flags(args, cls) -> dict:
    """The fields of `cls` given as flags on the command line."""
    return {f.name: getattr(args, f.name) for f in fields(cls) if hasattr(args, f.name)}


def as_dict(s) -> dict:
    """The settings as a plain dict (for settings.json)."""
    return {f.name: getattr(s, f.name) for f in fields(s)}
