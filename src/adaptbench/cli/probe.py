"""`adapt probe answers`: whether a model's next action follows the user's answer (llm/probe.py, docs/llm.md);
`adapt probe tasks`: whether its first action follows the task (llm/task_probe.py)."""

from __future__ import annotations

import json
import sys

HEADER = (f"{'model':<28} {'pairs':>5}  {'follows (prompts)':>17}  {'ignoring':>8}  {'both (pairs)':>12}  "
          f"{'ignoring':>8}  {'shift':>6}")


def _line(name: str, summary: dict) -> str:
    """One table line: the model's shares beside those of a model that ignores answers."""
    follows = f"{summary['share']:.1%} ± {summary['share_se']:.1%}"
    return (f"{name:<28} {summary['pairs']:>5}  {follows:>17}  {summary['ignoring_share']:>8.1%}  "
            f"{summary['pair_share']:>12.1%}  {summary['ignoring_pair_share']:>8.1%}  {summary['mean_shift']:>+6.2f}")


def _pairs(args):
    from ..compiler import load_domain
    from ..llm.probe import build_pairs, spread
    from .runs import _names, _seeds

    domain = load_domain(args.spec)
    tasks = _names(args.tasks, domain.task, "task")
    personas = _names(args.personas, domain.persona, "persona")
    pairs = build_pairs(domain, tasks, personas, _seeds(args.seeds), args.at, args.max_steps)
    return pairs, spread(pairs, args.limit)


def _score(args, model: str, pairs: list) -> dict:
    from ..llm.probe import backend_scorer, probe
    from ..progress import progress_bar
    from .model import _backend, resolve_model

    backend = _backend(args, resolve_model(model))
    with progress_bar(len(pairs), f"probe {model}", enabled=not args.quiet) as bar:
        result = probe(backend_scorer(backend), pairs, lambda done, total: bar.update())
    out = {"model": model, **result.summary()}
    if args.verbose:
        out["per_pair"] = [{"pair": s.pair.key(), "kind": s.pair.kind, "step": s.pair.step, "question": s.pair.question,
                            "answer_a": s.pair.a.answer, "action_a": s.pair.a.action,
                            "answer_b": s.pair.b.answer, "action_b": s.pair.b.action,
                            "under_a": list(s.under_a), "under_b": list(s.under_b),
                            "follows_a": s.follows_a, "follows_b": s.follows_b} for s in result.scores]
    return out


def _check_models(models: list) -> None:
    """Exit 2 with one line for a --model that is neither a directory nor a shipped model's name, before any
    pair is built."""
    from pathlib import Path

    from ..llm.named import NAMED
    from .model import resolve_model

    for m in models:
        if not Path(resolve_model(m)).is_dir():
            print(f"adapt: --model {m}: no such model directory (a directory saved with save_pretrained, or one of: "
                  f"{', '.join(NAMED)}; `adapt model init --out DIR` builds a random tiny one)", file=sys.stderr)
            raise SystemExit(2)


def _cmd_answers(args) -> int:
    if args.limit is not None and args.limit < 0:
        print(f"adapt: --limit must be 0 (all pairs) or more (got {args.limit})", file=sys.stderr)
        return 2
    _check_models(args.model)
    built, pairs = _pairs(args)
    if not pairs:
        print("adapt: no probe pairs for these tasks, personas and seeds (no preference answers a choice's "
              "question with an option another persona's answer contradicts)", file=sys.stderr)
        return 1
    rows = [_score(args, m, pairs) for m in args.model]
    if args.json:
        print(json.dumps({"pairs": len(pairs), "built": len(built), "at": args.at, "models": rows}, indent=1))
        return 0
    print(f"{len(pairs)} pairs (of {len(built)} built; question asked {'at the start' if args.at == 'start' else 'before its recipe'})")
    print(HEADER)
    for row in rows:
        print(_line(row["model"], row))
        for kind, part in row.get("by_kind", {}).items():
            print(_line(f"  {kind} choices", part))
        for p in row.get("per_pair", ()):
            mark = "".join("+" if f else "-" for f in (p["follows_a"], p["follows_b"]))
            print(f"  {mark} {p['pair']} @{p['step']}: {p['action_a']!r} | {p['action_b']!r}")
    return 0


def _cmd_tasks(args) -> int:
    from ..compiler import load_domain
    from ..llm.probe import backend_scorer
    from ..llm.task_probe import probe_tasks
    from ..progress import progress_bar
    from .model import _backend, resolve_model
    from .runs import _names, _seeds

    _check_models(args.model)
    domain = load_domain(args.spec)
    tasks = _names(args.tasks, domain.task, "task") or list(domain.task)
    if len(tasks) < 2:
        print("adapt: --tasks needs at least two tasks (the probe tells tasks apart)", file=sys.stderr)
        return 2
    personas = _names(args.personas, domain.persona, "persona") or list(domain.persona)
    seeds = _seeds(args.seeds)
    rows = []
    for model in args.model:
        backend = _backend(args, resolve_model(model))
        with progress_bar(len(personas) * len(seeds), f"probe {model}", enabled=not args.quiet) as bar:
            result = probe_tasks(backend_scorer(backend), domain, personas, seeds, tasks, lambda d, t: bar.update())
        rows.append({"model": model, **result.summary()})
    if args.json:
        print(json.dumps({"personas": personas, "seeds": list(seeds), "models": rows}, indent=1))
        return 0
    print(f"{rows[0]['prompts']} step-0 prompts ({len(personas)} persona(s) x {len(seeds)} scene seed(s) x {len(tasks)} tasks); "
          "a task is read right when its own first action (the oracle's) scores highest among the tasks' first actions")
    print(f"{'model':<28} {'read right':>10}  {'ignoring the task (at most)':>27}")
    for row in rows:
        print(f"{row['model']:<28} {row['share']:>10.1%}  {row['ignoring_share']:>27.1%}")
        for t, r in row["by_task"].items():
            wrong = {a: n for a, n in r["chosen"].items()} if r["right"] < r["prompts"] else {}
            print(f"  {t:<16} {r['right']:>3} / {r['prompts']:<3}" + (f"  chose: {wrong}" if wrong else ""))
    return 0


MODEL_HELP = "model directory, or `student` (the shipped tiny student); repeat for several"


def _scoring_options(q) -> None:
    """The options every probe takes for loading and scoring the models and for its output."""
    q.add_argument("--device", default="cpu", help="cpu, cuda, cuda:1 ... (default cpu)")
    q.add_argument("--dtype", choices=["auto", "float32", "bfloat16", "float16"],
                   help="default: the checkpoint's, or bfloat16 for a real-sized model on a CPU that has it")
    q.add_argument("--json", action="store_true", help="print the figures as JSON")
    q.add_argument("--quiet", action="store_true", help="no progress bar")


def _scope_options(q, tasks_help: str, personas: tuple, seeds: tuple) -> None:
    """A probe's --spec, --model (repeatable), --tasks, --personas and --seeds (`personas`, `seeds`: default
    and help)."""
    from .episode import add_spec_option

    add_spec_option(q)
    q.add_argument("--model", action="append", required=True, help=MODEL_HELP)
    q.add_argument("--tasks", default="all", help=tasks_help)
    q.add_argument("--personas", default=personas[0], help=personas[1])
    q.add_argument("--seeds", default=seeds[0], help=seeds[1])


def add_commands(sub) -> None:
    """Register `adapt probe answers` and `adapt probe tasks`."""
    p = sub.add_parser("probe", help="probe what a model does with what it is told: `adapt probe answers`, "
                                     "`adapt probe tasks`")
    psub = p.add_subparsers(dest="probe_command", metavar="SUBCOMMAND")
    q = psub.add_parser(
        "answers", help="the share of answer pairs whose next action follows the user's answer",
        description="Build pairs of planner prompts that differ only in the user's answer to one question (a "
                    "persona's preference answered to a recipe choice's question, against another persona's answer "
                    "that asks for another option), at the first step where the two answers' plans act differently; "
                    "report the share of prompts under which the model scores its answer's action above the other "
                    "(a model that ignores answers: 50%%) and of pairs that follow both answers (ignoring: 0%%), "
                    "one line per --model. Details: docs/llm.md.")
    _scope_options(q, "'all' or comma-separated task ids",
                   ("all", "'all' or comma-separated persona ids (answer A's persona)"),
                   ("0", "scene seeds, e.g. 0 or 0-3 (default 0)"))
    q.add_argument("--at", choices=["recipe", "start"], default="recipe",
                   help="where the question is asked: just before its choice's recipe, as the oracle-ask agent asks "
                        "(default), or as the first action")
    q.add_argument("--limit", type=int, default=200,
                   help="score at most this many pairs, taken evenly across all built (default 200; 0: all)")
    q.add_argument("--max-steps", type=int, default=50, help="step limit of the probe episodes (default 50)")
    _scoring_options(q)
    q.add_argument("--verbose", "-v", action="store_true", help="also each pair's actions and whether they were followed")
    q.set_defaults(func=_cmd_answers, backend="transformers", batch=None)
    t = psub.add_parser(
        "tasks", help="the share of tasks whose first action the model takes under their prompt",
        description="For each persona and scene seed, every task's step-0 planner prompt and the oracle's first "
                    "action of every task: report the share of prompts under which the model scores the task's own "
                    "first action highest, beside the most a model that ignores the task gets, and by task what it "
                    "chose where it read the task wrong (the shipped student reads tea and eggs as tea and toast). "
                    "Details: docs/training.md.")
    _scope_options(t, "'all' or comma-separated task ids (two at least)",
                   ("mark", "'all' or comma-separated persona ids (default mark)"),
                   ("0-3", "scene seeds, e.g. 0-3 (default 0-3)"))
    _scoring_options(t)
    t.set_defaults(func=_cmd_tasks, backend="transformers", batch=None)
