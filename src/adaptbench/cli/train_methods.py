"""`adapt train dpo|sft|no-reflection|star-gate` (adaptbench.training.trainers; docs/training.md): the
flags are built from each method's settings dataclass; `--config FILE.yaml` supplies any of them and the
flags given override it."""

from __future__ import annotations

import sys

from .episode import add_spec_option

DESCRIPTIONS = {
    "dpo": ("Reflection-DPO: DPO with a LoRA adapter on `adapt train data`'s pairs",
            "DPO (TRL) on the question/teacher rows of DATA/pairs.jsonl: chosen against the student's action, the "
            "reference being the adapter switched off. Every row is checked against --max-length; none is cut or "
            "dropped silently. Writes OUT/adapter and OUT/merged (a model directory for --model); running again "
            "resumes from the last checkpoint."),
    "sft": ("the \"no DPO\" ablation: supervised fine-tuning on the chosen completions",
            "Supervised fine-tuning (TRL) with a LoRA adapter on the chosen completions (questions and teacher "
            "actions) of DATA/pairs.jsonl, loss on the completion only."),
    "no-reflection": ("the \"no Reflection\" ablation: DPO on the teacher's actions only",
                      "DPO with a LoRA adapter, chosen a^t over a^s at every step of DATA/pairs.jsonl that reached "
                      "the decision rule (questions never chosen)."),
    "star-gate": ("the STaR-GATE baseline: SFT on the top third of the student's rollouts",
                  "Supervised fine-tuning with a LoRA adapter on the student's own actions in the top --top of its "
                  "`adapt rollout` results (--data: a JSONL file or a directory) by satisfaction rate, each step's "
                  "prompt rebuilt as the planner renders it."),
}


def _cmd(method: str):
    def run(args) -> int:
        import importlib.util
        from dataclasses import replace
        from pathlib import Path

        from ..install import install_hint
        from ..llm.named import resolve_model
        from ..training.trainers import METHODS, train
        from ..training.trainers.config import given_flags, load_settings

        cls = METHODS[method]
        s = load_settings(cls, given_flags(args, cls), args.config)  # usage errors first: they need no torch
        s = replace(s, model=resolve_model(s.model))  # `student`: the shipped tiny student
        missing = [m for m in ("torch", "transformers", "trl", "peft", "datasets") if importlib.util.find_spec(m) is None]
        if missing:
            print(f"adapt: train {method} needs {', '.join(missing)}: {install_hint('train')}", file=sys.stderr)
            return 1
        if not (Path(s.model) / "config.json").is_file():
            print(f"adapt: --model {s.model} is not a model directory (no config.json)", file=sys.stderr)
            return 2
        try:
            r = train(method, s, getattr(args, "spec", None))
        except KeyboardInterrupt:
            print(f"\nadapt: interrupted; run the same command again to resume from the last checkpoint in "
                  f"{Path(s.out) / 'checkpoints'}", file=sys.stderr)
            return 130
        last = r.get("last", {})
        figures = ", ".join(f"{k.split('/')[-1]} {last[k]:.4g}" for k in ("loss", "rewards/margins",
                                                                         "rewards/accuracies") if k in last)
        pace = f"{r['seconds_per_step']:.3f} s/step" if r.get("seconds_per_step") else "no step run now"
        print(f"{method}: {r['steps']} steps on {r['rows']} rows ({figures}); "
              f"{pace}; adapter in {Path(s.out) / 'adapter'}, merged model in "
              f"{Path(s.out) / 'merged'} (use it as --model)")
        return 0

    return run


def add_methods(train_sub) -> None:
    """Add dpo, sft, no-reflection and star-gate to the `train` group."""
    from ..training.trainers import METHODS
    from ..training.trainers.config import add_arguments

    for method, cls in METHODS.items():
        short, long = DESCRIPTIONS[method]
        p = train_sub.add_parser(method, help=short, description=long)
        if method == "star-gate":
            add_spec_option(p)
        add_arguments(p, cls)
        p.set_defaults(func=_cmd(method))
