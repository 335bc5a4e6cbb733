"""`adapt model curve`: the base student's learning curve (`training.curve`): behaviour cloning on the
oracle's episodes at one or more model sizes, evaluated at checkpoints on the split's unseen personas."""

from __future__ import annotations

import sys


def _fail(msg: str):
    print(f"adapt: {msg}", file=sys.stderr)
    raise SystemExit(2)


def parse_sizes(text: str) -> tuple:
    """'128x4,256x4' -> ((128, 4), (256, 4)); ValueError naming the bad part."""
    out = []
    for part in (p.strip() for p in text.split(",") if p.strip()):
        h, _, l_ = part.partition("x")
        if not (h.isdigit() and l_.isdigit() and int(h) > 0 and int(l_) > 0):
            raise ValueError(f"--sizes: '{part}' is not HIDDENxLAYERS (e.g. 128x4)")
        out.append((int(h), int(l_)))
    if not out:
        raise ValueError("--sizes: no size given (e.g. 128x4,256x4)")
    return tuple(out)


def _cmd_curve(args) -> int:
    from ..compiler import load_domain
    from ..harness.rollout import parse_seeds
    from ..harness.seeds import overlap_message
    from ..training.curve import CurveSettings, learning_curve
    from ..training.student import training_personas
    from .runs import _names

    domain = load_domain(args.spec)
    tasks = () if args.tasks == "all" else tuple(_names(args.tasks, domain.task, "task"))
    try:
        training_personas(domain, args.split)
        s = CurveSettings(split=args.split, seeds=tuple(parse_seeds(args.seeds)), sizes=parse_sizes(args.sizes),
                          steps=args.steps, every=args.every or args.steps, lr=args.lr, episodes=args.episodes,
                          max_steps=args.max_steps, batch=args.batch, seed=args.seed, threads=args.threads,
                          tasks=tasks, initial=args.initial)
    except ValueError as exc:
        _fail(str(exc))
    if min(s.steps, s.every, s.episodes, s.max_steps, s.batch, s.threads) < 1:
        _fail("--steps, --every, --episodes, --max-steps, --batch and --threads must be at least 1")
    line = overlap_message("--seeds", s.seeds)
    if line:
        _fail(line)
    curve = learning_curve(domain, args.out, s, log=lambda m: print(m, file=sys.stderr), progress=not args.quiet)
    for size in curve["sizes"]:
        last = size["points"][-1]
        print(f"{size['size']} ({size['parameters']:,} parameters): after {last['update']} updates, dishes "
              f"{last['dishes']}/{last['dishes_of']}, satisfaction {(last['satisfaction'] or 0):.1%} "
              f"± {(last['satisfaction_se'] or 0):.1%} on {last['episodes']} unseen episodes")
    print(f"curve in {args.out}/curve.json ({curve['seconds']:.0f} s)")
    return 0


def add_curve_command(msub) -> None:
    """Add `curve` to the `model` group."""
    from ..training.curve import CurveSettings
    from .episode import add_spec_option

    d = CurveSettings()
    q = msub.add_parser("curve", help="the base student's learning curve (oracle behaviour cloning, evaluated at "
                                      "checkpoints on unseen personas)",
                        description="Rolls out the oracle (no questions) on the split's training personas, trains a "
                                    "tiny model of each size on those episodes (one packed sequence per episode, loss "
                                    "on every action) and every --every updates rolls it out as the planner on "
                                    "--episodes episodes of the split's unseen personas (evaluation seeds 0-3, "
                                    "--max-steps steps). Writes OUT/curve.json and OUT/curve.png.")
    add_spec_option(q)
    q.add_argument("--out", required=True, help="directory (data, checkpoints, evaluation rollouts, curve.json)")
    q.add_argument("--split", default=d.split, help=f"split whose unseen personas are evaluated on (default {d.split})")
    q.add_argument("--seeds", default="100-103", help="scene seeds of the oracle episodes (default 100-103)")
    q.add_argument("--sizes", default="128x4,256x4", help="HIDDENxLAYERS, comma-separated (default 128x4,256x4)")
    q.add_argument("--tasks", default="all", help="'all' (default) or comma-separated task ids (training and evaluation)")
    q.add_argument("--steps", type=int, default=d.steps, help=f"updates, one packed episode each (default {d.steps})")
    q.add_argument("--every", type=int, default=d.every, help=f"evaluate every N updates (default {d.every})")
    q.add_argument("--lr", type=float, default=d.lr, help=f"default {d.lr}")
    q.add_argument("--episodes", type=int, default=d.episodes, help=f"evaluation episodes (default {d.episodes})")
    q.add_argument("--max-steps", type=int, default=d.max_steps, help=f"step budget (default {d.max_steps})")
    q.add_argument("--batch", type=int, default=d.batch, help=f"evaluation episodes stepped together (default {d.batch})")
    q.add_argument("--threads", type=int, default=d.threads, help="torch threads (default 1)")
    q.add_argument("--seed", type=int, default=d.seed, help="initialisation, data order, evaluation subset (default 0)")
    q.add_argument("--initial", action="store_true", help="also evaluate the untrained model (update 0; slow: "
                   "a random model's every step fails, so its episodes run to --max-steps)")
    q.add_argument("--quiet", action="store_true")
    q.set_defaults(func=_cmd_curve)
