"""Pretraining a (tiny) model on recorded trajectories rendered with the planner prompt, with TRL's
`SFTTrainer`: `adapt model pretrain --model DIR --data runs/oracle.jsonl --out DIR`.

Each record is replayed in the simulator (same scene, the offline user) to rebuild the view the agent
had at every step; the target is the recorded action followed by EOS after the rendered planner prompt
(`fit` to the token budget). Each step's untruncated prompt is a prefix of the next one's, so the steps
that fit the budget are packed into one sequence per episode (with no budget: the whole episode) and
one forward pass trains them all; a step whose prompt has to drop old steps is a sequence of its own.
A record whose replay does not reproduce its observations (another spec version) is skipped.

The sequences go to `SFTTrainer` as a tokenized dataset (`input_ids` + `completion_mask`, 1 on every
action and EOS token): TRL builds the labels from the mask (completion-only loss), never truncates
(`max_length=None`) and trains one sequence per update (AdamW, warm-up then linear decay, gradients
clipped at 1), on the CPU by default.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

IGNORE = -100  # label of a token the loss skips


def read_records(paths) -> list:
    """Episode records from JSONL files (error records and unreadable lines skipped)."""
    out = []
    for p in paths:
        for line in Path(p).read_text().splitlines():
            try:
                r = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(r, dict) and "steps" in r and "error" not in r:
                out.append(r)
    return out


def replay_views(domain, record):
    """(view, made_after, action) for each step of a record, rebuilt by replaying it (`training.replay`);
    None when the replay differs from the record."""
    from .replay import replay

    steps = replay(domain, record)
    return None if steps is None else [(v, m, s["action"]) for (v, m), s in zip(steps, record["steps"], strict=True)]


def examples(domain, records, tokenizer, budget: int | None = None, kind: str = "planner") -> tuple:
    """Training sequences `(ids, labels)` (labels: the target token, or IGNORE where there is no loss)
    and how many records were skipped. An episode's steps whose full prompt fits the budget are packed
    into one sequence (each step's prompt is a prefix of the next one's, so one pass trains them all);
    a later step, whose prompt drops old steps, is a sequence of its own."""
    from ..llm.prompts import PromptBuilder

    builder = PromptBuilder(domain, kind)
    out, skipped = [], 0
    for r in records:
        steps = replay_views(domain, r)
        if steps is None:
            skipped += 1
            continue
        out += episode_examples(builder, tokenizer, steps, budget)
    return out, skipped


def episode_examples(builder, tokenizer, steps, budget: int | None = None) -> list:
    """The `(ids, labels)` sequences of one replayed episode (see `examples`)."""
    packed, n = packed_example(builder, tokenizer, steps, budget)
    return ([packed] if packed else []) + [step_example(builder, tokenizer, s, budget) for s in steps[n:]]


def step_example(builder, tokenizer, step, budget: int | None) -> tuple:
    """One step: its prompt (`fit` to the budget) with no loss, then the action and EOS."""
    from ..llm.chat import fit, render

    view, made_after, action = step
    prompt = fit(tokenizer, lambda o: builder.prompt(view, omit=o, made_after=made_after), budget)
    p = tokenizer(render(tokenizer, prompt), add_special_tokens=False)["input_ids"]
    t = tokenizer(action, add_special_tokens=False)["input_ids"] + [tokenizer.eos_token_id]
    return p + t, [IGNORE] * len(p) + t


def packed_example(builder, tokenizer, steps, budget: int | None) -> tuple:
    """The longest run of leading steps whose untruncated prompts fit the budget as one sequence (the
    last of them with its action and EOS), labels on every action and EOS; and how many steps it holds.
    (None, 0) when the tokenizer does not split the conversation where the actions start and end (the
    action would then be tokenized differently in the history than when generated)."""
    from ..llm.chat import render

    eos = tokenizer.eos_token
    view, made_after, action = steps[-1]
    text = render(tokenizer, builder.prompt(view, made_after=made_after)) + action + eos
    spans = []
    for view, made_after, action in steps:
        start = len(render(tokenizer, builder.prompt(view, made_after=made_after)))
        if text[start:start + len(action) + len(eos)] != action + eos:
            return None, 0
        spans.append((start, action))
    enc = tokenizer(text, add_special_tokens=False, return_offsets_mapping=True)
    ids, begins = enc["input_ids"], {b: i for i, (b, _) in enumerate(enc["offset_mapping"])}
    labels, n, end = [IGNORE] * len(ids), 0, 0
    for start, action in spans:
        first = begins.get(start)
        target = tokenizer(action, add_special_tokens=False)["input_ids"] + [tokenizer.eos_token_id]
        if first is None or ids[first:first + len(target)] != target:
            return None, 0
        if budget is not None and first > budget:
            break
        labels[first:first + len(target)] = target
        n, end = n + 1, first + len(target)
    return ((ids[:end], labels[:end]) if n else None), n


# ------------------------------------------------------------------ TRL
def completion_dataset(data):
    """A tokenized `datasets.Dataset` for `SFTTrainer` from `(ids, labels)` sequences: `input_ids` and
    `completion_mask` (1 where the label is the token itself: the loss is on those tokens only)."""
    from datasets import Dataset

    for ids, labels in data:
        if any(t != IGNORE and t != i for i, t in zip(ids, labels, strict=True)):
            raise ValueError("a label differs from its token: a completion mask cannot express it")
    return Dataset.from_dict({"input_ids": [list(ids) for ids, _ in data],
                              "completion_mask": [[int(t != IGNORE) for t in labels] for _, labels in data]})


def sft_config(out, steps: int, lr: float, seed: int = 0, batch: int = 1, warmup: int = 50, log_every: int = 10,
               device: str = "cpu", **extra):
    """`SFTConfig` for training on already tokenized sequences with completion-only loss: no truncation,
    no checkpoints, no reports, no gradient checkpointing; float32 on a CPU (TRL defaults to bf16 and
    gradient checkpointing, both slow there); AdamW without weight decay, warm-up then linear decay."""
    from trl import SFTConfig

    cpu = device == "cpu"
    return SFTConfig(output_dir=str(out), max_steps=steps, learning_rate=lr, seed=seed, data_seed=seed,
                     per_device_train_batch_size=batch, gradient_accumulation_steps=1, max_length=None,
                     completion_only_loss=True, lr_scheduler_type="linear", warmup_steps=min(warmup, steps),
                     weight_decay=0.0, max_grad_norm=1.0, activation_checkpointing=False, bf16=False, fp16=False,
                     use_cpu=cpu, report_to="none", save_strategy="no", logging_steps=log_every,
                     disable_tqdm=True, dataloader_num_workers=0, **extra)


@dataclass(frozen=True)
class PretrainResult:
    """What `pretrain` did: labelled steps, episodes used and skipped, sequences, tokens, updates, the
    mean loss of the first and of the last (up to) 50 updates, and seconds spent training."""

    examples: int
    episodes: int
    skipped: int
    sequences: int
    tokens: int
    steps: int
    first_loss: float
    last_loss: float
    seconds: float


def _losses(history) -> list:
    return [h["loss"] for h in history if "loss" in h and "train_loss" not in h]


def _log_callback(log, steps: int):
    """A TrainerCallback printing the loss and the time left every 5% of the updates."""
    import time

    from transformers import TrainerCallback

    every = max(1, steps // 20)

    class Log(TrainerCallback):
        def on_train_begin(self, args, state, control, **kw):
            self.t0, self.window = time.perf_counter(), []

        def on_log(self, args, state, control, logs=None, **kw):
            if logs and "loss" in logs:
                self.window.append(logs["loss"])

        def on_step_end(self, args, state, control, **kw):
            i = state.global_step
            if i % every == 0 and self.window:
                spent = time.perf_counter() - self.t0
                log(f"update {i}/{steps} loss {sum(self.window) / len(self.window):.3f} "
                    f"({spent:.0f} s, ~{spent / i * (steps - i):.0f} s left)")
                self.window = []

    return Log()


def _checkpoint_callback(every: int, steps: int, on_checkpoint):
    """A TrainerCallback calling `on_checkpoint(update, model, recent_loss)` every `every` updates and after
    the last one (the model back in training mode afterwards)."""
    from transformers import TrainerCallback

    class Checkpoints(TrainerCallback):
        def on_train_begin(self, args, state, control, **kw):
            self.window = []

        def on_log(self, args, state, control, logs=None, **kw):
            if logs and "loss" in logs:
                self.window.append(logs["loss"])

        def on_step_end(self, args, state, control, model=None, **kw):
            i = state.global_step
            if i % every == 0 or i == steps:
                loss = sum(self.window) / len(self.window) if self.window else None
                self.window = []
                model.eval()
                on_checkpoint(i, model, loss)
                model.train()

    return Checkpoints()


def pretrain(domain, model_dir, data_paths, out, steps: int = 2000, lr: float = 3e-3, budget: int | None = None,
             seed: int = 0, threads: int = 1, log=print, every: int | None = None, on_checkpoint=None) -> PretrainResult:
    """Fine-tune the model in `model_dir` on the records in `data_paths` with TRL's `SFTTrainer`
    (completion-only loss on the actions); save the model and tokenizer to `out`. With `every` and
    `on_checkpoint`, `on_checkpoint(update, model, loss)` runs every `every` updates and after the last
    (the learning curve's evaluations; `loss`: the mean loss since the previous call)."""
    import tempfile
    import time

    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer, PrinterCallback, set_seed
    from trl import SFTTrainer

    torch.set_num_threads(threads)
    tok = AutoTokenizer.from_pretrained(model_dir)
    records = read_records(data_paths)
    data, skipped = examples(domain, records, tok, budget)
    if not data:
        raise ValueError(f"no training examples in {', '.join(map(str, data_paths))} "
                         f"({len(records)} records, {skipped} not reproducible with this spec)")
    targets = sum(1 for _, labels in data for t in labels if t == tok.eos_token_id)
    tokens = sum(len(ids) for ids, _ in data)
    log(f"{targets} steps of {len(records) - skipped} episodes ({skipped} skipped) in {len(data)} sequences, "
        f"{tokens} tokens")
    set_seed(seed)
    model = AutoModelForCausalLM.from_pretrained(model_dir, dtype=torch.float32)
    with tempfile.TemporaryDirectory() as scratch:  # the trainer's output_dir: nothing is saved there
        trainer = SFTTrainer(model=model, args=sft_config(scratch, steps, lr, seed, log_every=1),
                             train_dataset=completion_dataset(data), processing_class=tok,
                             callbacks=[_log_callback(log, steps)]
                             + ([_checkpoint_callback(every, steps, on_checkpoint)] if every and on_checkpoint else []))
        trainer.remove_callback(PrinterCallback)  # our callback logs instead (to `log`, not stdout)
        t0 = time.perf_counter()
        trainer.train()
        seconds = time.perf_counter() - t0
    out = Path(out)
    model.eval()
    out.mkdir(parents=True, exist_ok=True)
    trainer.model.save_pretrained(out)
    tok.save_pretrained(out)
    losses = _losses(trainer.state.log_history)
    head, tail = losses[:50], losses[-50:]
    return PretrainResult(targets, len(records) - skipped, skipped, len(data), tokens, steps,
                          sum(head) / max(1, len(head)), sum(tail) / max(1, len(tail)), seconds)
