"""`adapt train`: the training group. This module owns the group (`add_commands(sub)` builds the `train`
parser and its subparsers); `adapt train data` (Reflection-DPO's dataset) is added by `add_data`; other
modules add their methods through `REGISTRARS` (functions taking the group's subparsers), imported lazily.
"""

from __future__ import annotations

import json
import sys

from .argtypes import positive
from .episode import add_spec_option

REGISTRARS: list = []  # callables(train_sub) that add more `adapt train` subcommands


def _fail(msg: str, code: int = 2):
    print(f"adapt: {msg}", file=sys.stderr)
    raise SystemExit(code)


def _selection(args, domain) -> tuple:
    from ..harness.seeds import overlap_message
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
    seeds = tuple(_seeds(args.seeds))
    line = overlap_message("--seeds", seeds)
    if line and not args.allow_eval_seeds:
        _fail(line)
    return split, tuple(personas), tuple(_names(args.tasks, domain.task, "task")), seeds


def _model_dir(path: str, flag: str) -> None:
    from pathlib import Path

    if not (Path(path) / "config.json").is_file():
        _fail(f"{flag} {path} is not a model directory (no config.json); `adapt model init --out DIR` builds one")


def _workers(n: int) -> int:
    """--workers, at most one per CPU core (a worker holds a model copy and one torch thread)."""
    import os

    cores = os.cpu_count() or 1
    if n > cores:
        print(f"adapt: note: --workers {n} capped at {cores} (the CPU cores)", file=sys.stderr)
    return min(n, cores)


def _teacher(args, domain, student_backend):
    from ..llm.hf import TransformersBackend
    from ..training.relabel import LLMTeacher, ScriptedTeacher

    if not args.teacher_model:
        return ScriptedTeacher(domain)
    same = str(args.teacher_model).rstrip("/") == str(args.student).rstrip("/")
    backend = student_backend if same else TransformersBackend(args.teacher_model, device=args.device,
                                                               batch_size=args.batch)
    return LLMTeacher(backend, domain, args.teacher_model)


def _check_data_args(args) -> None:
    """Usage errors of `adapt train data` before anything heavy is imported (a shipped model's name, such
    as `student`, is resolved to its directory first)."""
    from pathlib import Path

    from ..llm.named import resolve_model

    args.student, args.teacher_model = resolve_model(args.student), resolve_model(args.teacher_model)
    if args.backend == "transformers":
        _model_dir(args.student, "--student")
    elif not Path(args.student).is_dir():
        _fail(f"--student {args.student} is not a directory: with --backend openai it is the student's local "
              "directory (its tokenizer and chat template render and encode every prompt; the weights are served)")
    if args.teacher_model:
        _model_dir(args.teacher_model, "--teacher-model")
    if args.workers > 1 and args.device != "cpu" and (args.backend == "transformers" or args.teacher_model):
        _fail("--workers above 1 forks the process, which a GPU context does not survive: use --workers 1 with "
              f"--device {args.device}")


def _recorded_selection(args, domain, split, personas, tasks, seeds) -> dict:
    """What defines a build of `adapt train data` (summary.json's `selection`): a rerun with the same is done."""
    return {"spec_hash": domain.spec_hash, "student": str(args.student), "teacher_model": args.teacher_model,
            "split": split, "personas": list(personas), "tasks": list(tasks), "seeds": list(seeds),
            "interactions": args.interactions, "questions": args.questions, "eps1": args.eps1, "eps2": args.eps2,
            "max_length": args.max_length, "max_steps": args.max_steps, "skip_after_failures": args.skip_after_failures,
            **({"skip_equivalent": True} if args.skip_equivalent else {}),
            **({"follow_questions": True} if args.follow_questions else {}),
            "temperature": args.temperature, "sample_seed": args.sample_seed,
            **({"question_set": args.question_set} if args.question_set != "free" else {}),
            **({"backend": "openai", "model": _served_name(args)} if args.backend == "openai" else {})}


def _served_name(args) -> str:
    """The served student's model name: --model, else --student (as the server names a model directory
    it was started on)."""
    return args.model or str(args.student)


def _student_backend(args):
    """The student's backend: the local model (--backend transformers) or the served one (--backend openai:
    the server probed, and checked to return prompt log-probabilities, before any episode; one line and
    exit 2 when it cannot be used)."""
    if args.backend == "transformers":
        from ..llm.hf import TransformersBackend

        return TransformersBackend(args.student, device=args.device, batch_size=args.batch,
                                   temperature=args.temperature, seed=args.sample_seed)
    from ..llm.backend import ModelError
    from .model import _backend

    args.tokenizer, args.server = args.student, "vllm"  # token-id prompts rendered by the student's tokenizer
    backend = _backend(args, _served_name(args))
    try:
        backend.check_scoring()
    except ModelError as exc:
        _fail(str(exc).splitlines()[0])
    return backend


def _already_built(store, chosen: dict) -> bool:
    """Whether OUT holds a finished build of this very selection (then say so: nothing is run again)."""
    from ..training.dataset import mix_line

    path = store.out / "summary.json"
    try:
        summary = json.loads(path.read_text()) if path.is_file() else {}
    except (OSError, ValueError):
        return False
    if not isinstance(summary, dict) or summary.get("selection") != chosen:
        return False
    print(f"adapt: {store.out} already holds this build ({summary.get('pairs')} steps, {path}); nothing to do "
          "(other personas, tasks or seeds into the same --out add to it)", file=sys.stderr)
    print(mix_line(summary))
    return True


def _cmd_data(args) -> int:
    _check_data_args(args)
    from ..training.dataset import PairStore

    store = PairStore(args.out, skip_bad=args.skip_bad_rows)  # a rerun's rows checked before anything heavy loads
    from ..compiler import load_domain
    from ..harness.workers import Interrupted, WorkerDied
    from ..llm.backend import ModelError
    from ..training.data import MAX_LENGTH, Builder, DataSettings, TooLong, build, opening_tokens
    from ..training.dataset import mix_line
    from ..training.relabel import student_policy

    domain = load_domain(args.spec)
    split, personas, tasks, seeds = _selection(args, domain)
    chosen = _recorded_selection(args, domain, split, personas, tasks, seeds)
    if _already_built(store, chosen):
        return 0
    backend = _student_backend(args)
    teacher = _teacher(args, domain, backend)
    settings = DataSettings(split, personas, tasks, seeds, args.interactions, args.questions, args.eps1, args.eps2,
                            args.max_length, args.batch, _workers(args.workers), args.max_steps,
                            args.skip_after_failures, args.skip_equivalent, args.follow_questions)
    need = opening_tokens(domain, student_policy(backend, domain, questions=args.question_set), settings)
    if need > args.max_length:
        _fail(f"--max-length {args.max_length} cannot hold a row's opening prompt (instructions, layout, task) and "
              f"its completion ({need} tokens): raise --max-length to at least {need}, more to keep questions and "
              f"answers (default {MAX_LENGTH})")

    def make_builder(sink):
        return Builder(domain, student_policy(backend, domain, questions=args.question_set), settings, sink,
                       args.student, teacher)

    def progress(done: int, total: int) -> None:
        print(f"\r{done}/{total} episodes, {len(store.rows)} steps", end="", file=sys.stderr, flush=True)

    resume = "re-run the same command to resume (the steps written are kept and skipped)"
    try:
        times = build(make_builder, settings, store, progress)
    except Interrupted as exc:
        print(f"\nadapt: stopped by {exc}; {len(store.rows)} steps are in {store.path}; {resume}", file=sys.stderr)
        return 130
    except WorkerDied as exc:
        print(f"\nadapt: {exc}; {len(store.rows)} steps are in {store.path}; {resume}", file=sys.stderr)
        return 1
    except TooLong as exc:
        print(f"\nadapt: {exc}; the {len(store.rows)} steps written are kept in {store.path}", file=sys.stderr)
        return 2
    except ModelError as exc:  # a served student's server gone or failing mid-run
        print(f"\nadapt: {str(exc).splitlines()[0]}; {len(store.rows)} steps are in {store.path}; {resume}",
              file=sys.stderr)
        return 2
    print(file=sys.stderr)
    summary = store.finish()
    summary["seconds"] = {k: round(v, 2) for k, v in times.seconds.items()}
    summary["teacher"] = teacher.name
    summary["teacher_model"] = teacher.model
    summary["interactions"] = args.interactions
    summary["max_steps"] = settings.max_steps
    summary["max_length"] = settings.max_length
    summary["skip_after_failures"] = settings.skip_after_failures
    summary["skip_equivalent"] = settings.skip_equivalent
    summary["follow_questions"] = settings.follow_questions
    if args.backend == "openai":
        summary["backend"] = backend.config() | {"url": args.url}
    summary["selection"] = chosen  # a rerun of the same selection is done (`_already_built`)
    (store.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(mix_line(summary))
    print("time: " + ", ".join(f"{k} {v:.1f}s" for k, v in summary["seconds"].items()))
    return 0


def add_data(train_sub) -> None:
    """Add `data` to the `train` group."""
    from ..grammars.emit import QUESTION_SETS
    from ..harness.seeds import EVAL_SEEDS, TRAIN_SEEDS, seeds_text

    p = train_sub.add_parser("data", help="build Reflection-DPO's preference pairs",
                             description="Roll out the student over the split's training personas; at each step "
                                         "the teacher (the scripted oracle, or an LLM with --teacher-model) "
                                         "relabels, the student reflects on a question, the user answers, and the "
                                         "decision rule picks chosen/rejected. Writes OUT/pairs.jsonl as it goes "
                                         "(running again resumes), then OUT/dataset/ and OUT/summary.json.")
    add_spec_option(p)
    p.add_argument("--split", help="split id of spec/splits.yaml (its unseen personas are left out)")
    p.add_argument("--student", required=True, help="the student's model directory, or `student` for the shipped tiny student")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--personas", default="all", help="'all' or comma-separated training persona ids")
    p.add_argument("--tasks", default="all", help="'all' or comma-separated task ids")
    p.add_argument("--seeds", default=TRAIN_SEEDS, help=f"scene seeds: 100-103 or 100,102 (default {TRAIN_SEEDS}); "
                   f"the evaluation seeds {seeds_text(EVAL_SEEDS)} are refused, so the student is never evaluated "
                   "on a scene it trained on")
    p.add_argument("--allow-eval-seeds", action="store_true",
                   help=f"train on the evaluation seeds {seeds_text(EVAL_SEEDS)} anyway (`adapt eval` then flags them)")
    p.add_argument("--interactions", type=int, default=1, choices=[1, 2], help="interactions per persona, task "
                   "and seed (2: the paper's data, the second with a summary of what the user answered in the "
                   "first as the student's prior knowledge)")
    p.add_argument("--questions", choices=["student", "topics", "choices"], default="student",
                   help="who proposes the question: the student from the reflection prompt (the paper); for a model "
                        "too small to write one, topics (a question about the preference the teacher named) or "
                        "choices (oracle-ask's question at the choice a^t realises, else as topics)")
    p.add_argument("--question-set", choices=QUESTION_SETS, default="free",
                   help="what the student's own Ask may say as it plays: free (any quoted text; default) or bank "
                        "(one of the domain's questions, as `adapt rollout --question-set bank` decodes it)")
    p.add_argument("--teacher-model", help="an LLM teacher's model directory: the privileged teacher prompt "
                   "(the persona's preferences, the unmet ones reminded each step) proposing a^t under the grammar "
                   "(default: the scripted oracle)")
    p.add_argument("--eps1", type=float, default=0.2, help="ε1: Δq above which the question is chosen (0.2)")
    p.add_argument("--eps2", type=float, default=0.5, help="ε2: Δt below which a^t is chosen (0.5)")
    p.add_argument("--max-length", type=positive, default=8192,
                   help="tokens of prompt plus completion per row (default 8192: the shipped students' prompts at "
                        "50 steps fit whole); a longer prompt loses its oldest observations first, never a "
                        "question, an answer or the task, and is scored on exactly what it keeps")
    p.add_argument("--batch", type=positive, default=8, help="episodes stepped together (default 8)")
    p.add_argument("--workers", type=positive, default=1, help="worker processes, each with a copy of the "
                   "models and --batch episodes in flight (default 1; at most the CPU cores)")
    p.add_argument("--max-steps", type=positive, default=50,
                   help="step budget per episode (default 50, the paper's, as in adapt rollout)")
    p.add_argument("--skip-after-failures", type=positive, metavar="N",
                   help="skip (no pair) the steps after N failed actions in a row: this project's option, not the "
                        "paper's (off by default: the looping states a correction should come from get pairs)")
    p.add_argument("--skip-equivalent", action="store_true",
                   help="skip (no pair) the steps where the student's action, followed by the oracle's plan, ends "
                        "the episode as well as the oracle's own action in no more steps (a step of the plan taken "
                        "out of order): this project's option for the scripted teacher, which carries out one plan "
                        "in one order, where the paper's LLM teacher would continue the student's own")
    p.add_argument("--follow-questions", action="store_true",
                   help="where the decision rule chooses the reflection's question, the rollout asks it instead of "
                        "taking the student's action (the row is the same: a^q chosen, a^s rejected), so the user's "
                        "reply is in the history of the steps after it and their rows are corrections with that "
                        "answer known: DAgger's mixture of the learner and the expert, with the reflection as the "
                        "expert of questions; this project's option (the paper's rollouts follow the student)")
    p.add_argument("--device", default="cpu", help="where the local student (and an LLM teacher) run (default cpu)")
    p.add_argument("--backend", choices=["transformers", "openai"], default="transformers",
                   help="where the student generates and scores: its local model (default), or an OpenAI-compatible "
                        "server such as vLLM (openai: --url, --model; prompts rendered and encoded by --student's "
                        "tokenizer and sent as token ids, Δq/Δt from the server's prompt log-probabilities)")
    p.add_argument("--url", default="http://localhost:8000/v1", help="the server (--backend openai; default "
                   "http://localhost:8000/v1)")
    p.add_argument("--model", help="the served student's name (--backend openai; default: --student, the name vLLM "
                   "gives the model directory it was started on)")
    p.add_argument("--skip-bad-rows", action="store_true", help="on a rerun, leave out the lines of OUT/pairs.jsonl "
                   "that are not rows (moved to pairs.jsonl.bad, counted and reported; their steps made again) "
                   "instead of stopping at the first (exit 2, naming its file:line)")
    from .model import add_sampling_options

    add_sampling_options(p, "")  # the student's actions and reflection questions
    p.set_defaults(func=_cmd_data)


def add_commands(sub) -> None:
    """Build the `train` group with `data` and every registrar's subcommands."""
    p = sub.add_parser("train", help="train agents (data, dpo, sft, no-reflection, star-gate, ...)", description="Build training data and train agents.")
    train_sub = p.add_subparsers(dest="train_command", metavar="COMMAND")
    add_data(train_sub)
    from .train_methods import add_methods

    add_methods(train_sub)
    from .reproduce import add_reproduce

    add_reproduce(train_sub)
    for registrar in REGISTRARS:
        registrar(train_sub)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])
