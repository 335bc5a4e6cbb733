"""`adapt train`: the training group. This module owns the group (`add_commands(sub)` builds the `train`
parser and its subparsers); `adapt train data` (Reflection-DPO's dataset) is added by `add_data`; other
modules add their methods through `REGISTRARS` (functions taking the group's subparsers), imported lazily.
"""

from __future__ import annotations

import sys

from .argtypes import positive
from .episode import add_spec_option

REGISTRARS: list = []  # callables(train_sub) that add more `adapt train` subcommands


def _fail(msg: str, code: int = 2):
    print(f"adapt: {msg}", file=sys.stderr)
    raise SystemExit(code)


def _selection(args, domain) -> tuple:
    from .runs import _names, _seeds

    split = None
    personas = list(domain.persona)
    if args.split is not None:
        unseen = {str(k): v for k, v in domain.unseen.items()}
        if args.split not in unseen:
            _fail(f"unknown split '{args.split}' (choose from: {', '.join(unseen) or 'none in spec/splits.yaml'})")
        split = next(k for k in domain.unseen if str(k) == args.split)
        personas = [p for p in personas if p not in unseen[args.split]]
    if args.personas != "all":
        personas = _names(args.personas, {p: None for p in personas}, "training persona")
    return split, tuple(personas), tuple(_names(args.tasks, domain.task, "task")), tuple(_seeds(args.seeds))


def _cmd_data(args) -> int:
    from pathlib import Path

    from ..compiler import load_domain
    from ..llm.hf import TransformersBackend
    from ..training.data import Builder, DataSettings
    from ..training.dataset import PairStore, mix_line
    from ..training.relabel import student_policy

    if not (Path(args.student) / "config.json").is_file():
        _fail(f"{args.student} is not a model directory (no config.json); `adapt model init --out DIR` builds one")
    if args.teacher_model:
        _fail("--teacher-model (an LLM teacher) is not implemented yet; the scripted oracle is the teacher", 1)
    domain = load_domain(args.spec)
    split, personas, tasks, seeds = _selection(args, domain)
    backend = TransformersBackend(args.student, device=args.device, batch_size=args.batch,
                                  temperature=args.temperature, seed=args.sample_seed)
    student = student_policy(backend, domain)
    settings = DataSettings(split, personas, tasks, seeds, args.interactions, args.questions, args.eps1, args.eps2,
                            args.max_length, args.batch)
    store = PairStore(args.out)
    builder = Builder(domain, student, settings, store, args.student)

    def progress(done: int, total: int) -> None:
        print(f"\r{done}/{total} episodes, {len(store.rows)} steps", end="", file=sys.stderr, flush=True)

    builder.run(progress)
    print(file=sys.stderr)
    summary = store.finish()
    summary["seconds"] = {k: round(v, 2) for k, v in builder.times.seconds.items()}
    print(mix_line(summary))
    print("time: " + ", ".join(f"{k} {v:.1f}s" for k, v in summary["seconds"].items()))
    return 0


def add_data(train_sub) -> None:
    """Add `data` to the `train` group."""
    p = train_sub.add_parser("data", help="build Reflection-DPO's preference pairs",
                             description="Roll out the student over the split's training personas; at each step "
                                         "the scripted oracle relabels, the student reflects on a question, the "
                                         "user answers, and the decision rule picks chosen/rejected. Writes "
                                         "OUT/pairs.jsonl as it goes (running again resumes), then OUT/dataset/ "
                                         "and OUT/summary.json.")
    add_spec_option(p)
    p.add_argument("--split", help="split id of spec/splits.yaml (its unseen personas are left out)")
    p.add_argument("--student", required=True, help="the student's model directory")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--personas", default="all", help="'all' or comma-separated training persona ids")
    p.add_argument("--tasks", default="all", help="'all' or comma-separated task ids")
    p.add_argument("--seeds", default="0", help="scene seeds: 0-3 or 0,2,5 (default 0)")
    p.add_argument("--interactions", type=positive, default=1, choices=[1], help="interactions per persona and "
                   "task (only 1 so far: the prior-knowledge summary for a second is not built yet)")
    p.add_argument("--questions", choices=["student", "topics"], default="student",
                   help="who proposes the question: the student from the reflection prompt, or the topic proposer")
    p.add_argument("--teacher-model", help="an LLM teacher's model directory (not implemented yet)")
    p.add_argument("--eps1", type=float, default=0.2, help="ε1: Δq above which the question is chosen (0.2)")
    p.add_argument("--eps2", type=float, default=0.5, help="ε2: Δt below which a^t is chosen (0.5)")
    p.add_argument("--max-length", type=positive, default=1024, help="tokens of prompt plus completion per row")
    p.add_argument("--batch", type=positive, default=8, help="episodes stepped together (default 8)")
    p.add_argument("--device", default="cpu")
    from .model import add_sampling_options

    add_sampling_options(p, "")  # the student's actions and reflection questions
    p.set_defaults(func=_cmd_data)


def add_commands(sub) -> None:
    """Build the `train` group with `data` and every registrar's subcommands."""
    p = sub.add_parser("train", help="train agents (data, ...)", description="Build training data and train agents.")
    train_sub = p.add_subparsers(dest="train_command", metavar="COMMAND")
    add_data(train_sub)
    for registrar in REGISTRARS:
        registrar(train_sub)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])
