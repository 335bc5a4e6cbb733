"""`adapt train reproduce --split S [--scale smoke|session] [--base DIR] --out DIR`: the whole study, resumable
(`training.pipeline`)."""

from __future__ import annotations

import os
import sys


def _cmd_reproduce(args) -> int:
    from dataclasses import replace
    from pathlib import Path

    from ..compiler import load_domain
    from ..training.pipeline import SCALES, BadBase, StageFailed, check_base, run, scale_dict, stages

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    domain = load_domain(args.spec)
    unseen = {str(k) for k in domain.unseen}
    if args.split not in unseen:
        print(f"adapt: unknown split '{args.split}' (choose from: {', '.join(sorted(unseen)) or 'none'})",
              file=sys.stderr)
        return 2
    if args.jobs < 1:
        print("adapt: --jobs must be at least 1", file=sys.stderr)
        return 2
    scale = SCALES[args.scale]
    if args.train_steps is not None:
        if args.train_steps < 1:
            print("adapt: --train-steps must be at least 1", file=sys.stderr)
            return 2
        scale = replace(scale, train_steps=args.train_steps)
    try:
        base = check_base(args.base, args.split) if args.base else None
    except BadBase as exc:
        print(f"adapt: {exc}", file=sys.stderr)
        return 2
    plan = stages(domain, args.split, scale, Path(args.out), args.spec, base)
    if args.estimate:
        from ..training.pipeline import estimate_lines

        print("\n".join(estimate_lines(plan, Path(args.out), args.jobs)))
        return 0
    try:
        rec = run(plan, Path(args.out), log, settings={"split": args.split, "scale": scale_dict(scale),
                                                       "base": base["base"] if base else None}, jobs=args.jobs)
    except StageFailed as exc:
        log(f"adapt: {exc}; fix it and run the same command again (the stages done are kept)")
        return 1
    except KeyboardInterrupt:
        log("\nadapt: interrupted; run the same command again to resume at the first stage not done")
        return 130
    print(f"reproduce ({args.scale}, split {args.split}) done in {rec['seconds_now']:.0f} s: Table 1/2 in "
          f"{args.out}/report/tables.md, figures in {args.out}/report/")
    return 0


def add_reproduce(train_sub) -> None:
    """Add `reproduce` to the `train` group."""
    from .episode import add_spec_option

    p = train_sub.add_parser("reproduce", help="the whole study in one resumable command: teacher data, base "
                                                "student, pairs, DPO and ablations, evaluation, tables and figures",
                             description="Runs teacher data -> base student (oracle behaviour cloning) -> its "
                                         "evaluation -> Reflection-DPO pairs -> dpo, no-reflection, sft, star-gate "
                                         "(each evaluated as soon as it is trained) -> Table 1/2 and the temporal and questions figures, each stage "
                                         "into OUT/<stage>/ with a done-marker. Prints its time estimate first; run "
                                         "again after a kill to resume at the first stage not done.")
    add_spec_option(p)
    p.add_argument("--split", required=True, help="split id of spec/splits.yaml (trained without its unseen personas)")
    p.add_argument("--scale", choices=["smoke", "session"], default="smoke",
                   help="smoke: a tiny model, one persona and task, a few steps (a few minutes; CI runs it); "
                        "session: the measured base recipe (128x4, 4,000 updates at lr 2e-3 on the oracle's "
                        "episodes of scene seeds 100-123) and everything after it at full size (see the estimate)")
    p.add_argument("--base", metavar="DIR",
                   help="an already trained base student (a model, its tokenizer and student.json, e.g. from adapt "
                        "model student or adapt model curve's OUT/<size>/final) instead of the base stage: it must "
                        "be trained for --split and on no evaluation scene seed (0-3)")
    p.add_argument("--train-steps", type=int, metavar="N",
                   help="optimizer steps of every trainer (dpo, no-reflection, sft, star-gate) instead of the "
                        "scale's (smoke 2, session 150): the same for every method, so the rows stay comparable")
    p.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1),
                   help="stages run side by side when they do not need each other (the base's evaluation, the "
                        "pairs and STaR-GATE after the base; dpo, no-reflection and sft after the pairs), each one "
                        "torch thread: default 2, or 1 on one core; 1 runs them in order. The results are the same")
    p.add_argument("--out", required=True, help="output directory (one folder per stage)")
    p.add_argument("--estimate", action="store_true", help="print the estimate and exit")
    p.set_defaults(func=_cmd_reproduce)
