"""Running a method: rows -> length check -> TRL trainer (LoRA through peft) -> adapter and merged model.

    result = train("dpo", settings, log=print)

OUT holds `settings.json` (the run's settings; resuming with other ones is refused, except the step
count, logging and threads), `long_rows.jsonl` (rows left out for length, with `--long-rows skip`),
`checkpoints/checkpoint-N` (every `save_steps` and at the end; a killed run resumes from the last one),
`log.jsonl` (one line per logged step), `adapter/` (the LoRA adapter and tokenizer), `merged/` (the base
model with the adapter merged in, a plain model directory every `--model` takes) and `train.json` (rows,
steps, losses, reward margins, seconds per step).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

from ...errors import AdaptError
from .config import as_dict
from .encode import Encoder, check_lengths, key_text

RESUMABLE = ("max_steps", "epochs", "save_steps", "logging_steps", "threads", "long_rows", "out", "skip_bad_rows",
             "allow_eval_seeds")


class TrainError(AdaptError):
    """A run that cannot start or go on (rows too long, another run's OUT): a failure."""

    exit_code = 1


@dataclass
class Prepared:
    """A method's rows in ids and what was left out (with why)."""

    rows: list
    left_out: dict = field(default_factory=dict)
    long: list = field(default_factory=list)
    seeds: tuple = ()  # the scene seeds of the data


def load_tokenizer(model: str):
    """The model directory's tokenizer (a pad token set to the end token when it has none)."""
    from transformers import AutoTokenizer

    tok = AutoTokenizer.from_pretrained(model)
    if tok.pad_token is None:
        tok.pad_token = tok.eos_token
    return tok


def vocabulary(model: str, tokenizer=None) -> int | None:
    """The ids the model embeds: its config.json's `vocab_size` (read without loading anything), else the
    tokenizer's size, else None (only negative ids are then refused)."""
    try:
        config = json.loads((Path(model) / "config.json").read_text())
        size = config.get("vocab_size") or (config.get("text_config") or {}).get("vocab_size")
    except (OSError, ValueError, AttributeError):
        size = None
    if isinstance(size, int) and size > 0:
        return size
    return len(tokenizer) if tokenizer is not None else None


@dataclass(frozen=True)
class Data:
    """A method's input as read and checked: the rows of pairs.jsonl (or STaR-GATE's rollout records) and
    the bad rows `--skip-bad-rows` left out."""

    rows: list
    bad: int = 0


def read_data(method: str, s, log=None, tokenizer=None) -> Data:
    """`s.data` read and every line checked before any model loads (a bad one stops the run naming its
    file:line, unless `s.skip_bad_rows`; `log`: where the rows left out are reported)."""
    from . import rows as R

    if method == "star-gate":
        from .stargate import read_rollouts_counted

        return Data(*read_rollouts_counted(s.data, s.agent, s.skip_bad_rows, log))
    return Data(*R.read_pairs(s.data, vocabulary(s.model, tokenizer), s.skip_bad_rows, log))


def prepare(method: str, s, tokenizer, spec=None, log=None, data: Data | None = None) -> Prepared:
    """The method's rows from `data` (default: `read_data`), every row length-checked against `s.max_length`
    (`spec`: the spec directory STaR-GATE replays its rollouts in)."""
    from . import rows as R

    data = data or read_data(method, s, log, tokenizer)
    enc = Encoder(tokenizer, s.layout)
    left: dict = {}
    if method == "star-gate":
        from ...compiler import load_domain
        from .stargate import split_of, stargate_rows, top_fraction

        records = data.rows
        kept = top_fraction(records, s.top)
        domain = load_domain(spec)
        try:
            encoded, bad = stargate_rows(domain, kept, enc, s.max_length)
        except (KeyError, TypeError) as exc:  # a record without a rollout record's fields
            raise R.DataError(f"--data {s.data}: a rollout record is malformed ({type(exc).__name__}: {exc})") from None
        left = {"rollouts": len(records), "rollouts_kept": len(kept), "rollouts_not_replayable": bad,
                "bad_rows_left_out": data.bad, "split": split_of(domain, records)}
        seeds = {r["seed"] for r in kept}
    else:
        pairs, repeats = _deduped(method, s, data.rows)
        build = {"dpo": R.dpo_rows, "sft": R.sft_rows,
                 "no-reflection": lambda p, e: R.no_reflection_rows(p, e, s.no_gain)}[method]
        try:
            encoded = build(pairs, enc)
        except (KeyError, TypeError, ValueError) as exc:  # a row without the dataset contract's fields
            raise R.DataError(f"--data {s.data}: a row of pairs.jsonl is malformed ({type(exc).__name__}: "
                              f"{exc}); rebuild it with `adapt train data`") from None
        left = {"pairs": len(data.rows) + data.bad, "bad_rows_left_out": data.bad}
        if s.dedupe_corrections:
            left["repeated_corrections_left_out"] = repeats
        seeds = {r.get("seed") for r in pairs}
    if not encoded:
        raise TrainError(f"--data {s.data}: no rows to train {method} on ({json.dumps(left)})")
    if s.mask_forced:
        encoded, left["forced_tokens_masked"] = _masked(encoded, tokenizer, spec)
    kept, long = check_lengths(encoded, s.max_length)
    return Prepared(kept, left, long, tuple(sorted(x for x in seeds if isinstance(x, int))))


def _masked(encoded: list, tokenizer, spec) -> tuple:
    """`--mask-forced`: the rows with the bank's forced question tokens out of the loss, and how many."""
    from ...compiler import load_domain
    from ...grammars.index import domain_questions
    from .rows import mask_forced_rows

    return mask_forced_rows(encoded, tokenizer, domain_questions(load_domain(spec)))


def _deduped(method: str, s, pairs: list) -> tuple:
    """The pairs a method builds its rows from, and how many `--dedupe-corrections` left out (0 without it):
    of the rows that reach the method's rule, each episode's first that chooses a given action."""
    from . import rows as R

    if not s.dedupe_corrections:
        return pairs, 0
    if method == "no-reflection":
        used = [r for r in pairs if R.reached_rule(r, s.no_gain)]
        kept, n = R.first_corrections(used, lambda r: r["teacher_action"])
    else:
        used = [r for r in pairs if r["kind"] in R.TRAINABLE]
        kept, n = R.first_corrections(used, lambda r: R.action_of(r["chosen"]))
    return kept, n


def scene_seeds(p: Prepared, s) -> tuple:
    """The scene seeds the trained model has seen: its data's and its base model's (`methods.trained_seeds`);
    TrainError when they meet the evaluation seeds 0-3, unless `s.allow_eval_seeds`."""
    from ...harness.methods import trained_seeds
    from ...harness.seeds import ALLOW_FLAG, eval_overlap, seeds_text

    bad = eval_overlap(p.seeds)
    if bad and not getattr(s, "allow_eval_seeds", False):
        raise TrainError(f"--data {s.data} holds episodes on the evaluation scene seeds {seeds_text(bad)}: train on "
                         f"scenes from 100 up (`adapt train data --seeds 100-103`, `adapt rollout --seeds 100-102` for "
                         f"STaR-GATE), or pass {ALLOW_FLAG} to train on them anyway", code=2)
    return tuple(sorted({*p.seeds, *trained_seeds(str(s.model))}))


def report_long(p: Prepared, s, out: Path) -> str | None:
    """Refuse (TrainError listing them) or, with `long_rows` skip, write them to OUT/long_rows.jsonl and
    return the line that says so; None when every row fits."""
    if not p.long:
        return None
    worst = max(p.long, key=lambda r: r.tokens)
    head = (f"{len(p.long)} of {len(p.long) + len(p.rows)} rows do not fit --max-length {s.max_length} (the "
            f"longest: {worst.tokens} tokens, prompt {worst.prompt_tokens}, {key_text(worst.key)})")
    if s.long_rows == "refuse":
        raise TrainError(f"{head}; raise --max-length, rebuild the data with a smaller `adapt train data "
                         "--max-length`, or pass --long-rows skip to leave them out (listed in OUT/long_rows.jsonl)")
    with (out / "long_rows.jsonl").open("w", encoding="utf-8") as f:
        for r in p.long:
            f.write(json.dumps({"key": list(r.key), "tokens": r.tokens, "prompt_tokens": r.prompt_tokens}) + "\n")
    if not p.rows:
        raise TrainError(f"{head}: no row is left to train on")
    return f"{head}: left out (--long-rows skip), listed in {out / 'long_rows.jsonl'}"


def _recorded(s) -> dict:
    """The settings as settings.json records them (the data and model as absolute paths)."""
    return {**as_dict(s), "data": str(Path(s.data).resolve()), "model": str(Path(s.model).resolve())}


def _defaults(s) -> dict:
    """Each setting's default (what a settings.json written before the setting existed ran with)."""
    from dataclasses import MISSING, fields

    return {f.name: f.default for f in fields(s) if f.default is not MISSING}


def check_resume(s, out: Path) -> None:
    """Refuse to go on with a run in OUT whose settings differ (but for RESUMABLE)."""
    path = out / "settings.json"
    now = _recorded(s)
    if path.is_file():
        before = {**_defaults(s), **json.loads(path.read_text())}  # a setting added since: its default
        diff = sorted(k for k in now if k not in RESUMABLE and before.get(k) != now[k])
        if diff:
            changes = ", ".join(f"{k} {before.get(k)} -> {now[k]}" for k in diff)
            raise TrainError(f"--out {out} holds a run with other settings ({changes}); use another --out or "
                             "the same settings to resume")


def write_settings(s, out: Path) -> None:
    """OUT/settings.json (once the trainer is built: settings it refused are not recorded)."""
    (out / "settings.json").write_text(json.dumps(_recorded(s), indent=2) + "\n")


def _state(ckpt: Path) -> dict | None:
    try:
        state = json.loads((ckpt / "trainer_state.json").read_text())
    except (OSError, ValueError):
        return None
    return state if isinstance(state, dict) and isinstance(state.get("global_step"), int) else None


def last_checkpoint(out: Path) -> str | None:
    """The newest complete checkpoint under OUT/checkpoints (its trainer state written whole), or None."""
    root = out / "checkpoints"
    done = [p for p in root.glob("checkpoint-*") if p.name.split("-")[-1].isdigit() and _state(p) is not None]
    return str(max(done, key=lambda p: int(p.name.split("-")[-1]))) if done else None


def checkpoint_step(checkpoint: str | None) -> int:
    """The optimizer steps a checkpoint holds (0 for none)."""
    return _state(Path(checkpoint))["global_step"] if checkpoint else 0


def finished(s, out: Path) -> dict | None:
    """OUT/train.json's content when OUT holds a finished run that reached the steps `s` asks for (its
    `--max-steps`, or its epochs over the rows the run trained on), else None. train.json is written
    last, after the adapter and the merged model: it marks a run done (with both still there)."""
    from .engine import steps_per_epoch

    try:
        result = json.loads((out / "train.json").read_text())
        steps, rows = result["steps"], result["rows"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    planned = s.max_steps or math.ceil(s.epochs * steps_per_epoch(s, rows))
    whole = (out / "adapter").is_dir() and (out / "merged" / "config.json").is_file()  # else saved again
    return result if steps >= planned and whole else None


def trim_log(out: Path, step: int) -> None:
    """Keep in OUT/log.jsonl only the lines of steps up to `step` (the checkpoint a run resumes from; 0: none):
    the steps after it are trained and logged again, once."""
    path = out / "log.jsonl"
    if not path.is_file():
        return
    keep = []
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        try:
            entry = json.loads(line)
        except ValueError:
            continue  # a torn line (a kill mid-write)
        if isinstance(entry, dict) and isinstance(entry.get("step"), int) and entry["step"] <= step:
            keep.append(line + "\n")
    tmp = path.with_name("log.jsonl.tmp")
    tmp.write_text("".join(keep), encoding="utf-8")
    os.replace(tmp, path)


def write_result(out: Path, result: dict) -> None:
    """OUT/train.json, written whole or not at all (the run's done-marker)."""
    tmp = out / "train.json.tmp"
    tmp.write_text(json.dumps(result, indent=2) + "\n")
    os.replace(tmp, out / "train.json")
