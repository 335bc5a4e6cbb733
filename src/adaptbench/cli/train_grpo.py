"""`adapt train grpo`: GRPO with TRL against the environment (envs.grpo; docs/environments.md, *TRL GRPO*).

`add_grpo(train_sub)` adds `grpo` to the `train` group's subparsers; `add_commands(sub)` (called after the
other command modules) adds it to an existing `train` group, or makes one holding only `grpo`.
"""

from __future__ import annotations

import sys

from .argtypes import positive, temperature
from .episode import add_spec_option


def _seeds(text: str) -> tuple:
    import argparse

    from ..harness.rollout import parse_seeds

    try:
        return tuple(parse_seeds(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _fraction(text: str) -> float:
    import argparse

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text} must be >= 0")
    return value


def _cmd_grpo(args) -> int:
    import importlib.util
    from pathlib import Path

    from ..install import install_hint

    missing = [m for m in ("torch", "transformers", "trl", "peft", "datasets") if importlib.util.find_spec(m) is None]
    if missing:
        print(f"adapt: train grpo needs {', '.join(missing)}: {install_hint('train')}", file=sys.stderr)
        return 1
    if args.temperature <= 0:
        print("adapt: train grpo needs --temperature above 0 (a group of identical greedy rollouts has no "
              "advantage to learn from)", file=sys.stderr)
        return 2
    from ..llm.named import resolve_model

    args.model = resolve_model(args.model)  # `student`: the shipped tiny student
    if not (Path(args.model) / "config.json").is_file():
        print(f"adapt: {args.model} is not a model directory (no config.json); build one with "
              "`adapt model init --out DIR`", file=sys.stderr)
        return 2
    from ..envs.grpo import GrpoSettings, train_grpo

    s = GrpoSettings(model=args.model, out=args.out, spec=args.spec, steps=args.steps, generations=args.generations,
                     max_completion=args.max_completion, max_tool_calls=args.max_tool_calls,
                     episode_steps=args.episode_steps, holdout=args.holdout, seeds=args.seeds,
                     eval_seeds=args.eval_seeds, eval_episodes=args.eval_episodes, learning_rate=args.lr,
                     format_reward=args.format_reward, seed=args.seed, tasks=tuple(args.task or ()),
                     temperature=args.temperature)
    try:
        r = train_grpo(s)
    except ValueError as exc:  # TRL's and transformers' refusals of a model or setting: one line, not a traceback
        print(f"adapt: train grpo: {' '.join(str(exc).split())[:400]}", file=sys.stderr)
        return 1
    if r.already:
        print(f"adapt: {args.out} already holds this finished run ({Path(args.out) / 'result.json'}); nothing to do",
              file=sys.stderr)
    fmt = lambda x: "n/a" if x is None else f"{x:.3f}"  # noqa: E731
    print(f"held-out reward (verifiers' satisfaction rate): before {fmt(r.before)}, after {fmt(r.after)}; "
          f"{len(r.rewards)} training steps logged to {Path(args.out) / 'log.jsonl'}; adapter in "
          f"{Path(args.out) / 'adapter'}")
    return 0


def add_grpo(train_sub) -> None:
    """Add `grpo` to the `train` group."""
    p = train_sub.add_parser("grpo", help="GRPO with TRL, the reward from the verifiers",
                             description="Train a LoRA adapter on MODEL with TRL's GRPOTrainer: each rollout is an "
                                         "ADAPT episode played with the tools act/ask/done; the reward is the "
                                         "episode's satisfaction rate. Reports the mean reward on held-out "
                                         "personas before and after. Running again with the same --out resumes.")
    add_spec_option(p)
    p.add_argument("--model", required=True, help="local model directory (e.g. from `adapt model init`)")
    p.add_argument("--out", default="runs/grpo", help="output directory (log.jsonl, checkpoints, adapter/)")
    p.add_argument("--steps", type=positive, default=20, help="optimizer steps (default 20)")
    p.add_argument("--generations", type=positive, default=4, help="rollouts per episode, the GRPO group (default 4)")
    p.add_argument("--max-completion", type=positive, default=256,
                   help="tokens the model may write in a whole episode, tool results excluded (default 256)")
    p.add_argument("--max-tool-calls", type=positive, default=8, help="tool-calling rounds per rollout (default 8)")
    p.add_argument("--episode-steps", type=positive, default=30, help="simulator step limit (default 30)")
    p.add_argument("--holdout", type=int, default=4, help="personas held out for the before/after reward (default 4)")
    p.add_argument("--seeds", type=_seeds, default=(100,),
                   help="training scene seeds (default 100: apart from the evaluation seeds 0-3)")
    p.add_argument("--eval-seeds", type=_seeds, default=(0,), help="held-out scene seeds (default 0)")
    p.add_argument("--eval-episodes", type=positive, default=8, help="held-out episodes measured (default 8)")
    p.add_argument("--task", action="append", help="train on this task only (repeatable; default all)")
    p.add_argument("--lr", type=float, default=5e-4, help="learning rate (default 5e-4)")
    p.add_argument("--format-reward", type=_fraction, default=0.1,
                   help="weight of the tool-call format shaping reward (default 0.1; 0 turns it off)")
    p.add_argument("--seed", type=int, default=0, help="training seed (default 0; also seeds the rollouts' sampling)")
    p.add_argument("--temperature", type=temperature, default=1.0,
                   help="sampling temperature of the rollouts (TRL's generation; default 1.0: a GRPO group needs "
                   "different samples)")
    p.set_defaults(func=_cmd_grpo)


def add_commands(sub) -> None:
    """Add `grpo` to the `train` group: into the group another module registered before this call, else
    into a `train` group of its own."""
    import argparse

    existing = sub.choices.get("train")
    if existing is not None:
        for action in existing._actions:  # argparse keeps a group's subcommands in this action
            if isinstance(action, argparse._SubParsersAction):
                add_grpo(action)
                return
    p = sub.add_parser("train", help="train agents (grpo)", description="Train agents.")
    train_sub = p.add_subparsers(dest="train_command", metavar="COMMAND")
    add_grpo(train_sub)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])
