"""`adapt train grpo`: GRPO with TRL on ADAPT episodes, the reward from the verifiers.

    result = train_grpo(GrpoSettings(model="models/tiny", out="runs/grpo", steps=20))   # spec=DIR: your own
    result.before, result.after          # mean reward on the held-out personas' episodes

The model is a local directory (any causal LM; a LoRA adapter is trained on it and saved to `out`). A
tokenizer whose chat template cannot render tool calls (the tiny model's) gets the Qwen3 chat format,
with its markers added as special tokens, so TRL can parse tool calls. Personas are split: the last
`holdout` (in spec order) are never trained on; the mean reward on their episodes is measured before and
after training with the trainer's own generation loop. Every log line goes to `out/log.jsonl` as it
comes; checkpoints every `save_every` steps; running again with the same `out` resumes.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

QWEN_MARKERS = ("<|im_start|>", "<|im_end|>", "<tool_call>", "</tool_call>", "<tool_response>", "</tool_response>",
                "<think>", "</think>")


@dataclass(frozen=True)
class GrpoSettings:
    """What `adapt train grpo` runs."""

    model: str
    out: str
    spec: str | None = None  # None: the paper's spec shipped with adaptbench
    steps: int = 20
    generations: int = 4
    max_completion: int = 256
    max_tool_calls: int = 8
    episode_steps: int = 30
    holdout: int = 4
    seeds: tuple = (0,)
    eval_seeds: tuple = (100,)
    eval_episodes: int = 8
    learning_rate: float = 5e-4
    lora_rank: int = 8
    format_reward: float = 0.1
    temperature: float = 1.0
    save_every: int = 50
    seed: int = 0
    tasks: tuple = field(default_factory=tuple)


@dataclass
class GrpoResult:
    """Mean held-out reward before and after, the training rewards logged, where the adapter went."""

    before: float | None = None
    after: float | None = None
    rewards: list = field(default_factory=list)
    out: str = ""
    already: bool = False  # a finished run found in `out`: nothing was trained


def split_personas(domain, holdout: int) -> tuple:
    """(training personas, held-out personas): the last `holdout` in spec order are held out (at least one
    persona is kept for training)."""
    ids = list(domain.persona)
    k = max(0, min(holdout, len(ids) - 1))
    return (ids[: len(ids) - k], ids[len(ids) - k:]) if k else (ids, ids)


def prepare_tokenizer(tokenizer, model):
    """Make the tokenizer render and parse tool calls: unchanged when its template already supports them;
    otherwise the Qwen3 chat template with its markers as special tokens (the model's embeddings grow to
    match and `<|im_end|>` ends a turn)."""
    from trl.chat_template_utils import qwen3_chat_template, supports_tool_calling

    if supports_tool_calling(tokenizer):
        return tokenizer
    tokenizer.add_special_tokens({"additional_special_tokens": list(QWEN_MARKERS)})
    tokenizer.chat_template = qwen3_chat_template
    tokenizer.eos_token = "<|im_end|>"
    model.resize_token_embeddings(len(tokenizer))
    model.config.eos_token_id = tokenizer.eos_token_id
    model.generation_config.eos_token_id = tokenizer.eos_token_id
    return tokenizer


class _JsonLog:
    """A trainer callback writing each log dict as one JSON line, flushed as it comes."""

    def __init__(self, path: Path, tag: dict):
        from transformers import TrainerCallback

        self.path, self.tag = path, tag
        outer = self

        class Callback(TrainerCallback):
            def on_log(self, args, state, control, logs=None, **kwargs):
                outer.write({"step": state.global_step, **(logs or {})})

        self.callback = Callback()

    def write(self, row: dict) -> None:
        with self.path.open("a", encoding="utf-8") as f:
            f.write(json.dumps({**self.tag, **row}) + "\n")


def _config(s: GrpoSettings, out: Path):
    from trl import GRPOConfig

    return GRPOConfig(output_dir=str(out), max_steps=s.steps, per_device_train_batch_size=s.generations,
                      per_device_eval_batch_size=s.generations, num_generations=s.generations,
                      num_generations_eval=s.generations, max_completion_length=s.max_completion,
                      max_tool_calling_iterations=s.max_tool_calls, learning_rate=s.learning_rate,
                      temperature=s.temperature, logging_steps=1, save_strategy="steps", save_steps=s.save_every,
                      report_to="none", use_cpu=_cpu(), gradient_checkpointing=False, seed=s.seed, beta=0.0,
                      reward_weights=[s.format_reward] if s.format_reward else None, disable_tqdm=True)


def _cpu() -> bool:
    import torch

    return not torch.cuda.is_available()


def build_trainer(s: GrpoSettings):
    """The GRPOTrainer for the settings, and the log writer."""
    import os

    os.environ.setdefault("TRL_EXPERIMENTAL_SILENCE", "1")
    from peft import LoraConfig
    from transformers import AutoModelForCausalLM, AutoTokenizer
    from trl import GRPOTrainer

    from ..compiler import load_domain
    from .trl_env import environment_class, episode_dataset, tool_format_reward

    domain = load_domain(s.spec)
    train_p, held_p = split_personas(domain, s.holdout)
    tasks = list(s.tasks) or None
    train = episode_dataset(domain, train_p, tasks, s.seeds).shuffle(seed=s.seed)
    held = episode_dataset(domain, held_p, tasks, s.eval_seeds).shuffle(seed=s.seed)
    held = held.select(range(min(s.eval_episodes, len(held))))
    tokenizer = AutoTokenizer.from_pretrained(s.model)
    model = AutoModelForCausalLM.from_pretrained(s.model, dtype="float32")
    tokenizer = prepare_tokenizer(tokenizer, model)
    if tokenizer.pad_token is None:
        tokenizer.pad_token = tokenizer.eos_token
    tokenizer.padding_side = "left"
    out = Path(s.out)
    out.mkdir(parents=True, exist_ok=True)
    lora = LoraConfig(r=s.lora_rank, lora_alpha=2 * s.lora_rank, target_modules="all-linear", task_type="CAUSAL_LM")
    log = _JsonLog(out / "log.jsonl", {"spec_hash": domain.spec_hash})
    trainer = GRPOTrainer(model=model, args=_config(s, out), train_dataset=train, eval_dataset=held,
                          processing_class=tokenizer, peft_config=lora,
                          reward_funcs=[tool_format_reward] if s.format_reward else None,
                          environment_factory=environment_class(domain, s.episode_steps), callbacks=[log.callback])
    return trainer, log, (train_p, held_p)


def _held_out_reward(trainer) -> float | None:
    """Mean environment reward (the verifiers' rate) on the held-out episodes, one evaluation pass."""
    metrics = trainer.evaluate()
    key = next((k for k in metrics if k.endswith("rewards/AdaptEnvironment/mean")), None)
    return metrics.get(key) if key else None


def _last_checkpoint(out: Path):
    ckpts = sorted(out.glob("checkpoint-*"), key=lambda p: int(p.name.split("-")[-1]))
    return str(ckpts[-1]) if ckpts else None


DONE = "result.json"  # written last: a run with it (and the same settings) is finished


def finished(s: GrpoSettings) -> GrpoResult | None:
    """The result of a finished run of these settings in `s.out` (its result.json), else None."""
    path = Path(s.out) / DONE
    try:
        data = json.loads(path.read_text()) if path.is_file() else None
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("settings") != vars_of(s):
        return None
    return GrpoResult(data.get("before"), data.get("after"), list(data.get("rewards") or ()), str(s.out), True)


def train_grpo(s: GrpoSettings) -> GrpoResult:
    """Train, measuring the held-out reward before and after; the adapter and tokenizer go to `s.out`, then
    result.json (the run's done-marker). A finished run of the same settings is not trained again."""
    done = finished(s)
    if done is not None:
        return done
    trainer, log, (train_p, held_p) = build_trainer(s)
    out = Path(s.out)
    log.write({"event": "start", "train_personas": train_p, "held_out_personas": held_p, "settings": vars_of(s)})
    result = GrpoResult(out=str(out))
    result.before = _held_out_reward(trainer)
    log.write({"event": "held_out", "when": "before", "reward": result.before})
    trainer.train(resume_from_checkpoint=_last_checkpoint(out))
    result.after = _held_out_reward(trainer)
    log.write({"event": "held_out", "when": "after", "reward": result.after})
    result.rewards = [h["reward"] for h in trainer.state.log_history if "reward" in h and "eval_reward" not in h]
    trainer.save_model(str(out / "adapter"))
    trainer.processing_class.save_pretrained(str(out / "adapter"))
    tmp = out / (DONE + ".tmp")
    tmp.write_text(json.dumps({"settings": vars_of(s), "before": result.before, "after": result.after,
                               "rewards": result.rewards}, indent=1) + "\n")
    tmp.replace(out / DONE)
    return result


def vars_of(s: GrpoSettings) -> dict:
    """The settings as JSON-friendly values."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in s.__dict__.items()}
