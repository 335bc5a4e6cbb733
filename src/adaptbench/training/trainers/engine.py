"""The TRL side: the trainer of a method over pre-tokenized rows, LoRA through peft, checkpoints, progress,
the adapter and the merged model.

DPO uses TRL's `DPOTrainer` with `_prepare_dataset` passed through (TRL 1.16 always re-tokenizes text
rows and has no switch for rows already in ids; the rows come from `encode`, checked for length, and
`max_length=None` keeps TRL from cutting or dropping any). The reference is the base model: the adapter
switched off (no second copy). SFT uses `SFTTrainer` on `input_ids` + `labels` rows, which TRL takes as
they are. Both train in float32 on a CPU (TRL's bfloat16 and gradient checkpointing defaults are off).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from .config import DPOSettings
from .run import TrainError

METRICS = ("loss", "rewards/margins", "rewards/accuracies", "rewards/chosen", "rewards/rejected",
           "mean_token_accuracy", "learning_rate", "grad_norm")


IDLE = {"seconds": 0.0, "steps_run": 0, "seconds_per_step": None, "cpu_seconds_per_step": None}  # no step run


@dataclass(frozen=True)
class Trained:
    """What a finished training holds: its optimizer steps and its log history (TRL's log dicts)."""

    steps: int
    history: list


def is_main() -> bool:
    """Whether this is the main process (`accelerate launch` sets RANK; one process: yes)."""
    return int(os.environ.get("RANK", "0")) == 0


def world_size() -> int:
    """Processes training together (`accelerate launch` sets WORLD_SIZE)."""
    return int(os.environ.get("WORLD_SIZE", "1"))


def steps_per_epoch(s, rows: int) -> int:
    """Optimizer steps in one pass over `rows`."""
    return math.ceil(rows / (s.batch * s.grad_accum * world_size()))


def precompute(s, rows: int) -> bool:
    """Whether to precompute the reference log-probs: yes/no as set; auto when the run sees every row at least
    once (the pass up front then costs no more than the reference forward of every step it replaces)."""
    if s.precompute_ref != "auto":
        return s.precompute_ref == "yes"
    return s.max_steps is None or s.max_steps >= steps_per_epoch(s, rows)


def _precision(s) -> tuple:
    import torch

    cuda = torch.cuda.is_available()
    if s.precision == "auto":
        return cuda, bool(cuda and torch.cuda.is_bf16_supported())
    return cuda, s.precision == "bfloat16"


def trainer_args(s, out: Path, rows: int) -> dict:
    """The TrainingArguments shared by the methods."""
    cuda, bf16 = _precision(s)
    return dict(output_dir=str(out / "checkpoints"), max_steps=s.max_steps or -1, num_train_epochs=s.epochs,
                per_device_train_batch_size=s.batch, gradient_accumulation_steps=s.grad_accum, learning_rate=s.lr,
                logging_steps=s.logging_steps, save_strategy="steps", save_steps=s.save_steps, save_total_limit=2,
                report_to="none", use_cpu=not cuda, bf16=bf16, gradient_checkpointing=s.gradient_checkpointing,
                seed=s.seed, data_seed=s.seed, disable_tqdm=True, max_length=None, dataloader_num_workers=0)


def lora(s):
    """The adapter's peft config."""
    from peft import LoraConfig

    return LoraConfig(r=s.lora_r, lora_alpha=s.lora_alpha, lora_dropout=s.lora_dropout, target_modules=s.targets(),
                      task_type="CAUSAL_LM")


def load_model(s):
    """The student (float32 on a CPU; bfloat16 where the run trains in it)."""
    import torch
    from transformers import AutoModelForCausalLM

    _, bf16 = _precision(s)
    return AutoModelForCausalLM.from_pretrained(s.model, dtype=torch.bfloat16 if bf16 else torch.float32)


KEEP = ("chosen_keep", "rejected_keep")  # per completion token, 0 where the loss skips it (`--mask-forced`)


def _dpo_class():
    from trl import DPOTrainer

    class TokenizedDPOTrainer(DPOTrainer):
        """DPOTrainer over rows already in ids (prompt_ids, chosen_ids, rejected_ids), length-checked; rows
        with keep masks keep them through to the collator."""

        def _prepare_dataset(self, dataset, processing_class, args, dataset_name):
            missing = {"prompt_ids", "chosen_ids", "rejected_ids"} - set(dataset.column_names)
            if missing:
                raise ValueError(f"{dataset_name} rows lack {', '.join(sorted(missing))}")
            return dataset

        def _set_signature_columns_if_needed(self):
            super()._set_signature_columns_if_needed()
            self._signature_columns = [*self._signature_columns, *KEEP]

    return TokenizedDPOTrainer


def keep_mask_collator(pad_token_id: int):
    """TRL's preference collator whose completion mask is 0 where a row's keep mask is: the DPO sums, the
    reference log-probs and the `sft` term all read that mask, so a skipped token counts nowhere."""
    from trl.trainer.dpo_trainer import DataCollatorForPreference

    class KeepMaskCollator(DataCollatorForPreference):
        def torch_call(self, examples):
            out = super().torch_call([{k: v for k, v in e.items() if k not in KEEP} for e in examples])
            mask, n = out["completion_mask"], len(examples)
            for i, e in enumerate(examples):
                start = len(e["prompt_ids"])
                for row, side in ((i, "chosen"), (n + i, "rejected")):
                    keep = e[f"{side}_keep"]
                    mask[row, start:start + len(keep)] *= mask.new_tensor(keep)
            return out

    return KeepMaskCollator(pad_token_id=pad_token_id, max_length=None)


def progress_callback(out: Path, log):
    """A transformers callback: a line per logged step through `log` (step, loss, reward margin and accuracy,
    time left) and a JSON line in OUT/log.jsonl (main process only)."""
    from transformers import TrainerCallback

    class Progress(TrainerCallback):
        def __init__(self):
            self.t0, self.first = time.perf_counter(), 0

        def on_train_begin(self, args, state, control, **kw):
            self.first, self.t0 = state.global_step, time.perf_counter()

        def on_log(self, args, state, control, logs=None, **kw):
            logs = logs or {}
            if not state.is_world_process_zero or "train_runtime" in logs:  # the end's totals: train.json's
                return
            with (out / "log.jsonl").open("a", encoding="utf-8") as f:
                f.write(json.dumps({"step": state.global_step, **logs}) + "\n")
            if "loss" in logs:
                log(_line(state, logs, self.first, time.perf_counter() - self.t0))

    return Progress()


def _line(state, logs: dict, first: int, spent: float) -> str:
    done = state.global_step - first
    left = spent / done * (state.max_steps - state.global_step) if done else 0.0
    shown = " ".join(f"{k.split('/')[-1]} {logs[k]:.4g}" for k in METRICS[:3] if k in logs)
    return f"step {state.global_step}/{state.max_steps} {shown} ({spent:.0f} s, ~{left:.0f} s left)"


def build(method: str, s, rows: list, tokenizer, out: Path, log, anchor=None):
    """The TRL trainer of the method over the encoded rows (transformers' own printing of every log dict
    replaced by `Progress`); with `anchor` (an `anchor.AnchorStream`), each forward also trains that many
    teacher episodes (`--anchor`)."""
    from transformers import PrinterCallback

    trainer = _build(method, s, rows, tokenizer, out, log, anchor)
    trainer.remove_callback(PrinterCallback)
    return trainer


def _with_anchor(cls, s, anchor):
    if anchor is None:
        return cls
    from .anchor import anchored

    return anchored(cls, anchor, s.anchor_per_update, s.anchor_weight)


def _build(method: str, s, rows: list, tokenizer, out: Path, log, anchor=None):
    import warnings

    os.environ.setdefault("TRL_EXPERIMENTAL_SILENCE", "1")
    warnings.filterwarnings("ignore", message=r".*(is_)?gradient_checkpointing` is deprecated", category=FutureWarning)
    from datasets import Dataset

    model = load_model(s)
    common = trainer_args(s, out, len(rows))
    callbacks = [progress_callback(out, log)]
    try:
        if isinstance(s, DPOSettings):
            from trl import DPOConfig

            pre = precompute(s, len(rows))
            args = DPOConfig(**common, beta=s.beta, loss_type=s.loss.split("+"), precompute_ref_log_probs=pre,
                             precompute_ref_batch_size=max(s.batch, 8))
            data = Dataset.from_list([r.preference() for r in rows])
            masked = rows[0].chosen_keep is not None
            collator = keep_mask_collator(_pad_id(tokenizer)) if masked else None
            return _with_anchor(_dpo_class(), s, anchor)(model=model, args=args, train_dataset=data, processing_class=tokenizer,
                                peft_config=lora(s), callbacks=callbacks, data_collator=collator)
        from trl import SFTConfig, SFTTrainer

        args = SFTConfig(**common, packing=False)
        data = Dataset.from_list([r.supervised() for r in rows])
        return _with_anchor(SFTTrainer, s, anchor)(model=model, args=args, train_dataset=data, processing_class=tokenizer,
                          peft_config=lora(s), callbacks=callbacks)
    except ValueError as exc:  # peft's and TRL's refusals (no such target module, a bad setting)
        raise TrainError(f"train {method}: {' '.join(str(exc).split())[:400]}") from None


def _pad_id(tokenizer) -> int:
    """The pad token TRL's own collator would take: the tokenizer's pad token, else its EOS."""
    return tokenizer.pad_token_id if tokenizer.pad_token_id is not None else tokenizer.eos_token_id


def replace_dir(tmp: Path, final: Path) -> None:
    """Put the finished directory `tmp` in place of `final` (a kill leaves the one or the other whole)."""
    if final.exists():
        shutil.rmtree(final)
    os.replace(tmp, final)


def _partial(path: Path) -> Path:
    tmp = path.with_name(path.name + ".partial")
    if tmp.exists() and is_main():
        shutil.rmtree(tmp)  # a killed run's
    return tmp


def save_adapter(trainer, out: Path) -> None:
    """The trained adapter into OUT/adapter.partial (`finish_adapter` puts it in place)."""
    trainer.save_model(str(_partial(out / "adapter")))


ADAPTER_FILES = ("adapter_config.json", "adapter_model.safetensors", "adapter_model.bin", "README.md")


def from_checkpoint(checkpoint: str, out: Path) -> Trained:
    """The adapter of a checkpoint that finished the training, copied into OUT/adapter.partial, and its
    steps and log history."""
    ckpt = Path(checkpoint)
    state = json.loads((ckpt / "trainer_state.json").read_text())
    tmp = _partial(out / "adapter")
    tmp.mkdir(parents=True)
    for name in ADAPTER_FILES:
        if (ckpt / name).is_file():
            shutil.copy2(ckpt / name, tmp / name)
    return Trained(state["global_step"], state.get("log_history", []))


def finish_adapter(out: Path, tokenizer) -> None:
    """The tokenizer beside the adapter in OUT/adapter.partial, then the whole put in place as OUT/adapter."""
    tmp = out / "adapter.partial"
    tokenizer.save_pretrained(str(tmp))
    replace_dir(tmp, out / "adapter")


def merge(model_dir: str, adapter: Path, merged: Path, tokenizer) -> None:
    """The base model with the adapter merged in, saved as a plain model directory (the base's dtype),
    written beside and then put in place of `merged`."""
    import warnings

    from peft import PeftModel
    from transformers import AutoModelForCausalLM

    warnings.filterwarnings("ignore", message=r".*(is_)?gradient_checkpointing` is deprecated", category=FutureWarning)
    base = AutoModelForCausalLM.from_pretrained(model_dir, dtype="auto")
    model = PeftModel.from_pretrained(base, str(adapter)).merge_and_unload()
    tmp = _partial(merged)
    model.save_pretrained(str(tmp))
    tokenizer.save_pretrained(str(tmp))
    replace_dir(tmp, merged)


def summary_of(history: list) -> dict:
    """Losses and DPO reward figures from a trainer's log history."""
    hist = [h for h in history if "loss" in h]
    out = {}
    if hist:
        out["first"] = {k: hist[0][k] for k in METRICS if k in hist[0]} | {"step": hist[0].get("step")}
        out["last"] = {k: hist[-1][k] for k in METRICS if k in hist[-1]} | {"step": hist[-1].get("step")}
    return out


def fit(trainer, resume: str | None, log) -> dict:
    """Train (from `resume` when given); returns the seconds (wall, and this process's CPU time: the figure
    that a shared machine disturbs least) and steps of this invocation."""
    start = trainer.state.global_step
    t0, c0 = time.perf_counter(), time.process_time()
    trainer.train(resume_from_checkpoint=resume)
    spent, cpu = time.perf_counter() - t0, time.process_time() - c0
    steps = trainer.state.global_step - (int(Path(resume).name.split("-")[-1]) if resume else start)
    return {"seconds": round(spent, 2), "steps_run": steps,
            "seconds_per_step": round(spent / steps, 4) if steps else None,
            "cpu_seconds_per_step": round(cpu / steps, 4) if steps else None}


def stderr(msg: str) -> None:
    """A progress line on stderr."""
    print(msg, file=sys.stderr, flush=True)
