"""`adapt rollout` and `adapt eval`: run agents over the benchmark and tabulate the results."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..paper import default_spec
from .episode import add_spec_option


def _names(text: str, pool: dict, what: str) -> list:
    if text == "all":
        return list(pool)
    names = list(dict.fromkeys(x.strip() for x in text.split(",") if x.strip()))
    bad = [n for n in names if n not in pool]
    if bad or not names:
        print(f"adapt: unknown {what} {', '.join(bad) or '(none given)'} "
              f"(choose from: {', '.join(pool)}, or all)", file=sys.stderr)
        raise SystemExit(2)
    return names


def _seeds(text: str) -> list:
    from ..harness.rollout import parse_seeds

    try:
        return parse_seeds(text)
    except ValueError as exc:
        print(f"adapt: bad --seeds '{text}': {exc} (use 0-3 or 0,2,5)", file=sys.stderr)
        raise SystemExit(2) from None


def _grid(args, domain) -> list:
    from ..harness.registry import names
    from ..harness.rollout import Job

    agents = list(dict.fromkeys(a.strip() for a in args.agent.split(",") if a.strip()))
    known = names()
    bad = [a for a in agents if a not in known]
    if bad or not agents:
        print(f"adapt: unknown agent {', '.join(bad) or '(none given)'} "
              f"(choose from: {', '.join(known)})",
              file=sys.stderr)
        raise SystemExit(2)
    if args.workers < 1:
        print(f"adapt: --workers must be at least 1 (got {args.workers})", file=sys.stderr)
        raise SystemExit(2)
    personas = _names(args.personas, domain.persona, "persona")
    tasks = _names(args.tasks, domain.task, "task")
    seeds = _seeds(args.seeds)
    return [Job(a, p, t, s) for a in agents for p in personas for t in tasks for s in seeds]


def _cmd_rollout(args) -> int:
    """Every agent, scripted or model, on the one rollout path (`harness.rollout.rollout`); for model
    agents the backend is built here and handed in."""
    from ..compiler import load_domain
    from ..harness.results import ResultsError
    from ..harness.rollout import rollout
    from ..harness.workers import Interrupted, WorkerDied
    from .model import rollout_options

    domain = load_domain(args.spec)
    jobs = _grid(args, domain)
    options = rollout_options(args, [j.agent for j in jobs])
    resume = "re-run the same command to resume (finished episodes are kept and skipped)"
    try:
        res = rollout(jobs, Path(args.out), workers=args.workers, progress=not args.quiet, domain=domain, **options)
    except Interrupted as exc:
        print(f"\nadapt: stopped by {exc}; every finished episode is in {args.out}; {resume}", file=sys.stderr)
        return 130
    except WorkerDied as exc:
        print(f"adapt: {exc}; finished episodes are in {args.out}; {resume}", file=sys.stderr)
        return 1
    except ResultsError as exc:
        tail = f"; {resume}" if exc.code == 1 and Path(args.out).is_file() else ""
        print(f"adapt: {exc}{tail}", file=sys.stderr)
        return exc.code
    _summary(res, len(jobs), args.out)
    return 1 if res.errors else 0


def _summary(res, total: int, out: str) -> None:
    print(f"{res.ran} episode(s) run, {res.present} already in {out}"
          + (f", {res.errors} ended in an error (traceback in the record)" if res.errors else ""))
    for line in res.error_samples:
        print(f"  error: {line}", file=sys.stderr)


def _load_runs(args, paths=None):
    from ..harness.records import load_runs, mixed_specs

    paths = paths or args.runs
    runs = load_runs(paths, _splits(args))  # a RunsError goes to the one handler: its message, its code
    mixed = mixed_specs(runs)
    if mixed and not args.allow_mixed:
        print(f"adapt: {mixed}", file=sys.stderr)
        raise SystemExit(1)
    if runs.skipped:
        print(f"adapt: {runs.skipped_text()}", file=sys.stderr)
    if runs.unversioned:
        print(f"adapt: note: {runs.unversioned} record(s) predate versioned records (read as version 0)",
              file=sys.stderr)
    if not runs.records:
        print(f"adapt: no usable episode records in {', '.join(paths)}", file=sys.stderr)
        raise SystemExit(1)
    return runs


def _splits(args):
    """The domain's splits (split id -> unseen persona ids), loaded on first use: only records of trained
    agents carry a `split`."""
    from functools import cache

    @cache
    def unseen() -> dict:
        from ..compiler import load_domain

        return load_domain(args.spec).unseen
    return unseen


def _tables(args, records: list) -> tuple:
    """(rows, text, csv thunk, markdown thunk, notes): a `--by` breakdown, or the paper's tables."""
    if args.by:
        from ..harness import breakdown as b

        rows = b.breakdown(records, args.by)
        return (rows, b.render_text(rows, args.by), lambda: b.render_csv(rows, args.by),
                lambda: b.render_markdown(rows, args.by), [])
    from .evaluation import tables

    return tables(args, records, _splits(args))


def _write_out(path: str, text: str) -> None:
    try:
        Path(path).write_text(text)
    except OSError as exc:
        print(f"adapt: cannot write {path} ({exc.strerror})", file=sys.stderr)
        raise SystemExit(1) from None


def _cmd_eval(args) -> int:
    from ..harness.sampled import by_temperature, sampling_notes
    from . import evaluation

    mapped = evaluation.mapping(args)
    runs = _load_runs(args, evaluation.run_files(args, mapped))
    resolved = evaluation.resolve(runs, mapped, _splits(args))
    records = by_temperature(resolved)  # seeds averaged, temperatures apart
    evaluation.one_budget(args, records)
    records, ceiling_note = evaluation.with_ceiling(args, records)
    rows, text, csv_text, md_text, lines = _tables(args, records)
    markdown_out = args.markdown == "-"
    paired = evaluation.paired_texts(args, records, _splits(args))  # exit 2 before any table
    print(md_text() if markdown_out else text)  # the Markdown holds the notes
    if paired:
        print("\n" + paired[markdown_out])
    none = sum(1 for r in records if r.satisfaction_rate is None)
    if none and not args.by:
        print(f"{none} episode(s) had no applicable preference and are left out of the satisfaction rates")
    for line in [*([] if markdown_out else lines), *sampling_notes(records), *evaluation.seed_notes(runs, resolved),
                 *ceiling_note]:
        print(line)
    if args.plot:
        _plot(args.plot, rows if not args.by else _agent_rows(args, records), records)
    evaluation.figures(args, records)
    if args.csv:
        _write_out(args.csv, csv_text() + "\n")
    if args.markdown and not markdown_out:
        _write_out(args.markdown, md_text() + ("\n\n" + paired[1] if paired else "") + "\n")
    return 0


def _agent_rows(args, records: list) -> list:
    from ..harness.evaluate import table

    return table(records, _splits(args)() if any(r.split is not None for r in records) else None)


def _plot(path: str, rows: list, records: list) -> None:
    from ..errors import AdaptError
    from ..harness.plots import draw

    try:
        draw(rows, records, Path(path))
    except AdaptError:
        raise  # PlotsUnavailable: the one handler prints it
    except (OSError, ValueError) as exc:
        print(f"adapt: cannot write the plot {path} ({getattr(exc, 'strerror', None) or exc})", file=sys.stderr)
        raise SystemExit(1) from None


def _cmd_users_check(args) -> int:
    from ..compiler import load_domain
    from ..qa.fidelity import check

    if getattr(args, "llm", False):
        from .model import users_check_llm

        return users_check_llm(args)
    results, summary = check(load_domain(args.spec))
    misses = [r for r in results if not r.hit]
    if args.verbose:
        for r in misses:
            print(f"MISS {r.persona}.{r.preference}: {r.question!r} -> {r.answer!r}")
    print(f"offline user: {summary['hits']}/{summary['probes']} probes answered with the right preference "
          f"({summary['hit_rate']:.1%}); consistent answers: {'yes' if summary['consistent'] else 'NO'}; "
          f"location leaks: {summary['location_leaks']}")
    return 0 if summary["hit_rate"] >= args.min_rate and summary["location_leaks"] == 0 else 1


def _cmd_check_solvable(args) -> int:
    from ..compiler import load_domain
    from ..qa.solvable import unsolved

    domain = load_domain(args.spec)
    personas = _names(args.personas, domain.persona, "persona")
    tasks = _names(args.tasks, domain.task, "task")
    rows = unsolved(args.spec, personas, tasks, _seeds(args.seeds), args.workers)
    for persona, task, seed, pref, reason in rows:
        print(f"{persona}/{task} seed {seed}: {pref}: {reason}")
    print(f"{len(rows)} applicable preference(s) the oracle could not satisfy")
    return 1 if rows else 0


def _grid_options(p, seeds_help: str) -> None:
    add_spec_option(p)
    p.add_argument("--personas", default="all", help="'all' or comma-separated ids")
    p.add_argument("--tasks", default="all", help="'all' or comma-separated ids")
    p.add_argument("--seeds", default="0-3", help=seeds_help)
    p.add_argument("--workers", type=int, default=1,
                   help="parallel processes (default 1; for a model on the CPU each holds a copy and batches "
                        "--batch episodes: data parallelism across cores)")


class AgentsHelp(argparse.HelpFormatter):
    """Fills `{agents}` in a help text with the registry's agents (read when the help is shown, so that
    building the parser imports nothing and reads no entry points)."""

    def _get_help_string(self, action) -> str:
        text = super()._get_help_string(action) or ""
        if "{agents}" in text:
            from ..harness.registry import registry

            listed = "; ".join(f"{s.name} ({s.description})" if s.description else s.name for s in registry().values())
            text = text.replace("{agents}", listed.replace("%", "%%"))
        return text


def add_commands(sub) -> None:
    """Register rollout and eval."""
    p = sub.add_parser("rollout", help="run agents over personas x tasks x seeds into a JSONL file",
                       formatter_class=AgentsHelp,
                       description="Run episodes and append one JSON line each to --out as they finish. "
                                   "Re-running the same command resumes: episodes already in the file are skipped.")
    _grid_options(p, "scene seeds, e.g. 0-3 or 0,4,9 (default 0-3)")
    p.add_argument("--agent", required=True, help="comma-separated for several: {agents}")
    p.add_argument("--out", required=True, help="results file, e.g. runs/oracle.jsonl")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    from . import model as llm_cli

    llm_cli.add_rollout_options(p)
    p.set_defaults(func=_cmd_rollout)
    llm_cli.add_commands(sub)

    p = sub.add_parser("eval", help="print the paper's Table 1 and Table 2 from rollout files",
                       description="Preference satisfaction rate and questions asked (mean ± standard error) "
                                   "for seen and unseen personas under the cross-validation splits of spec/splits.yaml "
                                   "(each trained method on the split it was trained on), pass^k and question "
                                   "precision, in the layout of the paper's Table 1 and Table 2 (definitions: "
                                   "docs/evaluation.md).")
    p.add_argument("runs", nargs="*", help="JSONL files written by adapt rollout")
    p.add_argument("--spec", default=default_spec(), help="spec directory whose splits.yaml defines seen/unseen personas "
                                                  "(read only for records with a `split`) and whose simulator replays "
                                                  "episodes for --plot-temporal (default: spec)")
    p.add_argument("--csv", help="also write the tables as CSV")
    p.add_argument("--markdown", nargs="?", const="-", metavar="PATH",
                   help="also write the tables as Markdown to PATH; with no PATH (or -), print them as Markdown "
                        "instead of the text tables")
    p.add_argument("--plot", help="also draw satisfaction per agent and per persona (PNG, SVG or PDF by suffix; needs the plots extra)")
    p.add_argument("--by", choices=["task", "persona", "preference"],
                   help="break the results down per task, persona or preference instead of the seen/unseen table")
    p.add_argument("--allow-mixed", action="store_true",
                   help="evaluate results of different spec versions or step budgets together (refused by default: "
                        "a table compares methods at one --max-steps; each row shows its budget)")
    p.add_argument("--no-ceiling", action="store_true",
                   help="without oracle records, do not compute the oracle's ceiling row at the records' budget")
    from .evaluation import add_options

    add_options(p)
    p.set_defaults(func=_cmd_eval)

    p = sub.add_parser("users", help="offline user tools: `adapt users check`")
    usub = p.add_subparsers(dest="users_command", metavar="SUBCOMMAND")
    q = usub.add_parser("check", help="probe the offline user with a question per preference and report the hit rate",
                        description="For every preference, ask questions a planner would ask about it and check that "
                                    "the offline user answers with that preference; also checks consistency and that "
                                    "object locations are never revealed. Exit 1 below --min-rate.")
    add_spec_option(q)
    q.add_argument("--min-rate", type=float, default=0.95, help="fail below this hit rate (default 0.95)")
    q.add_argument("--verbose", "-v", action="store_true", help="list the probes that missed")
    llm_cli.add_users_check_options(q)
    q.set_defaults(func=_cmd_users_check)

    p = sub.add_parser("check-solvable", help="report applicable preferences the oracle cannot satisfy",
                       description="Run the oracle on every persona x task x seed; print every applicable preference "
                                   "it violates. Each is a spec bug or needs an availability condition. Exit 1 if any.")
    _grid_options(p, "scene seeds (default 0-3)")
    p.set_defaults(func=_cmd_check_solvable)
