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

With a checkpoint directory, training is resumable: the trainer's own checkpoints (`save_strategy="steps"`:
model, optimizer, scheduler, RNG states and the trainer state with its loss history) are written to
DIR/checkpoint-N every `save_every` updates and after the last (the two newest kept), and DIR/pretrain.json
records the run's settings. Run again with the same settings, training resumes from the newest complete
checkpoint (one whose trainer_state.json, written last, is there) with `trainer.train(resume_from_checkpoint=)`;
once a run has finished, pretrain.json holds its result and running it again is a no-op. Other settings on
the same directory are refused (one line), never mixed.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

from .answer_rows import answer_examples, read_rows

IGNORE = -100  # label of a token the loss skips


def json_objects(paths):
    """The JSON objects of JSONL files, line by line (unreadable lines and non-objects skipped)."""
    for p in paths:
        for line in Path(p).read_text().splitlines():
            try:
                r = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(r, dict):
                yield r


def read_records(paths) -> list:
    """Episode records from JSONL files (error records and unreadable lines skipped)."""
    return [r for r in json_objects(paths) if "steps" in r and "error" not in r]


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
               device: str = "cpu", save_every: int | None = None, accumulate: int = 1, **extra):
    """`SFTConfig` for training on already tokenized sequences with completion-only loss: no truncation,
    no reports, no gradient checkpointing; float32 on a CPU (TRL defaults to bf16 and gradient
    checkpointing, both slow there); AdamW without weight decay, warm-up then linear decay. No checkpoints,
    or with `save_every` the trainer's full checkpoints in `out` every that many updates and after the
    last, the two newest kept. `accumulate`: sequences whose gradients make one update (one at a time: no
    padding)."""
    from trl import SFTConfig

    cpu = device == "cpu"
    save = ({"save_strategy": "steps", "save_steps": save_every, "save_total_limit": 2} if save_every
            else {"save_strategy": "no"})
    return SFTConfig(output_dir=str(out), max_steps=steps, learning_rate=lr, seed=seed, data_seed=seed,
                     per_device_train_batch_size=batch, gradient_accumulation_steps=accumulate, max_length=None,
                     completion_only_loss=True, lr_scheduler_type="linear", warmup_steps=min(warmup, steps),
                     weight_decay=0.0, max_grad_norm=1.0, activation_checkpointing=False, bf16=False, fp16=False,
                     use_cpu=cpu, report_to="none", logging_steps=log_every, disable_tqdm=True,
                     dataloader_num_workers=0, **save, **extra)


@dataclass(frozen=True)
class PretrainResult:
    """What `pretrain` did: labelled steps, episodes used and skipped, sequences, tokens, updates, the
    mean loss of the first and of the last (up to) 50 updates, seconds spent training in this call, and
    the update it resumed from (0: from the initialisation)."""

    examples: int
    episodes: int
    skipped: int
    sequences: int
    tokens: int
    steps: int
    first_loss: float
    last_loss: float
    seconds: float
    resumed_from: int = 0


def _losses(history) -> list:
    return [h["loss"] for h in history if "loss" in h and "train_loss" not in h]


# ------------------------------------------------------------------ checkpoints
RUN_FILE = "pretrain.json"  # in the checkpoint directory: the run's settings, and its result once finished


def file_sha256(path) -> str:
    """The SHA-256 of a file's bytes, read in 1 MiB chunks (model weights, data files)."""
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def run_settings(model_dir, data_paths, steps: int, lr: float, budget, seed: int, accumulate: int = 1,
                 rows_context: str = "full") -> dict:
    """What makes two pretraining runs the same run: the starting model (its weights' hash), the data
    (each file's hash), updates, learning rate, token budget and seed, and (when not their defaults, so that
    older runs still resume) the sequences an update and the answer rows' context."""
    weights = sorted(Path(model_dir).glob("*.safetensors"))
    extra = {**({"accumulate": accumulate} if accumulate != 1 else {}),
             **({"rows_context": rows_context} if rows_context != "full" else {})}
    return {"model": [file_sha256(w) for w in weights], "data": [file_sha256(p) for p in data_paths], "steps": steps,
            "lr": lr, "budget": budget, "seed": seed, **extra}


def last_checkpoint(folder) -> tuple:
    """(update, path) of the newest complete trainer checkpoint in `folder` (DIR/checkpoint-N holding its
    trainer_state.json, which the trainer writes last); (0, None) when there is none."""
    found = []
    for d in Path(folder).glob("checkpoint-*"):
        n = d.name.removeprefix("checkpoint-")
        if n.isdigit() and (d / "trainer_state.json").is_file():
            found.append((int(n), d))
    return max(found) if found else (0, None)


def _open_run(folder: Path, settings: dict) -> dict:
    """The run record of a checkpoint directory: created with `settings` when absent; ValueError (one line)
    when it holds another run's."""
    path = folder / RUN_FILE
    if path.is_file():
        rec = json.loads(path.read_text())
        if rec.get("settings") != settings:
            diff = [k for k in settings if rec.get("settings", {}).get(k) != settings[k]]
            raise ValueError(f"{folder} holds the checkpoints of another pretraining run (different "
                             f"{', '.join(diff) or 'settings'}): remove it, or train into another directory")
        return rec
    if last_checkpoint(folder)[1] is not None:
        raise ValueError(f"{folder} holds checkpoints but no {RUN_FILE}: remove it, or train into another directory")
    folder.mkdir(parents=True, exist_ok=True)
    rec = {"settings": settings}
    _write_json(path, rec)
    return rec


def _write_json(path: Path, obj) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(obj, indent=1) + "\n")
    tmp.replace(path)  # atomic: a kill leaves the old file or the new one


def _log_callback(log, steps: int):
    """A TrainerCallback printing the loss and the time left every 5% of the updates."""
    import time

    from transformers import TrainerCallback

    every = max(1, steps // 20)

    class Log(TrainerCallback):
        def on_train_begin(self, args, state, control, **kw):
            self.t0, self.window, self.start = time.perf_counter(), [], None

        def on_log(self, args, state, control, logs=None, **kw):
            if logs and "loss" in logs:
                self.window.append(logs["loss"])

        def on_step_end(self, args, state, control, **kw):
            i = state.global_step
            if self.start is None:
                self.start = i - 1  # the update resumed from (0 on a fresh run)
            if i % every == 0 and self.window:
                spent = time.perf_counter() - self.t0
                log(f"update {i}/{steps} loss {sum(self.window) / len(self.window):.3f} "
                    f"({spent:.0f} s, ~{spent / (i - self.start) * (steps - i):.0f} s left)")
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
             seed: int = 0, threads: int = 1, log=print, every: int | None = None, on_checkpoint=None,
             checkpoints=None, save_every: int | None = None, device: str = "cpu", accumulate: int = 1,
             rows_context: str = "full") -> PretrainResult:
    """Fine-tune the model in `model_dir` on the records in `data_paths` with TRL's `SFTTrainer`
    (completion-only loss on the actions); save the model and tokenizer to `out`. With `every` and
    `on_checkpoint`, `on_checkpoint(update, model, loss)` runs every `every` updates and after the last
    (the learning curve's evaluations; `loss`: the mean loss since the previous call). With `checkpoints`
    (a directory), the trainer's state is saved there every `save_every` updates (default: `every`, else
    200) and a rerun with the same settings resumes from the newest complete checkpoint, or returns the
    finished run's result without training (see the module docstring); ValueError when the directory
    holds another run's checkpoints. `device`: where the trainer trains (cpu, or cuda: the trainer's
    own device choice, float32 weights either way); a run may resume on another device. `accumulate`:
    sequences an update (gradients summed one at a time); `rows_context`: what of an answer row's prompt is
    trained on (`answer_rows.CONTEXTS`)."""
    import time

    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer, PrinterCallback, set_seed
    from trl import SFTTrainer

    out = Path(out)
    run = None
    if checkpoints is not None:
        checkpoints = Path(checkpoints)
        run = _open_run(checkpoints, run_settings(model_dir, data_paths, steps, lr, budget, seed, accumulate, rows_context))
        if "result" in run and (out / "config.json").is_file():
            log(f"already trained: {steps} updates (checkpoints in {checkpoints}); nothing to do")
            return PretrainResult(**run["result"])
    torch.set_num_threads(threads)
    tok = AutoTokenizer.from_pretrained(model_dir)
    records = read_records(data_paths)
    data, skipped = examples(domain, records, tok, budget)
    answers = read_rows(data_paths)  # answer-following rows (`answer_rows`), beside the episodes
    data += answer_examples(answers, tok, rows_context)
    if not data:
        raise ValueError(f"no training examples in {', '.join(map(str, data_paths))} "
                         f"({len(records)} records, {skipped} not reproducible with this spec)")
    targets = sum(1 for _, labels in data for t in labels if t == tok.eos_token_id)
    tokens = sum(len(ids) for ids, _ in data)
    log(f"{targets} steps of {len(records) - skipped} episodes ({skipped} skipped)"
        + (f" and {len(answers)} answer rows" if answers else "") + f" in {len(data)} sequences, {tokens} tokens")
    set_seed(seed)
    model = AutoModelForCausalLM.from_pretrained(model_dir, dtype=torch.float32)
    resumed, start = last_checkpoint(checkpoints) if checkpoints is not None else (0, None)
    if start is not None:
        log(f"resuming from update {resumed} of {steps} ({start})")
    with _trainer_dir(checkpoints) as folder:
        args = sft_config(folder, steps, lr, seed, log_every=1, device=device, accumulate=accumulate,
                          save_every=(save_every or every or 200) if checkpoints is not None else None)
        trainer = SFTTrainer(model=model, args=args, train_dataset=completion_dataset(data), processing_class=tok,
                             callbacks=[_log_callback(log, steps)]
                             + ([_checkpoint_callback(every, steps, on_checkpoint)] if every and on_checkpoint else []))
        trainer.remove_callback(PrinterCallback)  # our callback logs instead (to `log`, not stdout)
        # each sequence weighs the same in an accumulated update, as in a one-sequence update (not each target
        # token: TRL's default there, under which an answer row's one action would weigh 1/30 of an episode)
        if accumulate > 1:
            trainer.model_accepts_loss_kwargs = False
        t0 = time.perf_counter()
        trainer.train(resume_from_checkpoint=str(start) if start is not None else None)
        seconds = time.perf_counter() - t0
    model.eval()
    out.mkdir(parents=True, exist_ok=True)
    trainer.model.save_pretrained(out)
    tok.save_pretrained(out)
    losses = _losses(trainer.state.log_history)
    head, tail = losses[:50], losses[-50:]
    result = PretrainResult(targets, len(records) - skipped, skipped, len(data), tokens, steps,
                            sum(head) / max(1, len(head)), sum(tail) / max(1, len(tail)), seconds, resumed)
    if run is not None:
        _write_json(checkpoints / RUN_FILE, {**run, "result": asdict(result)})
    return result


def _trainer_dir(checkpoints):
    """The trainer's output directory: the checkpoint directory, or a temporary one (nothing saved there)."""
    import contextlib
    import tempfile

    if checkpoints is None:
        return tempfile.TemporaryDirectory()
    return contextlib.nullcontext(str(checkpoints))
