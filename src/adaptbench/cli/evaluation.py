"""The paper's parts of `adapt eval` (wired in `cli/runs.py`): which method each record belongs to
(`--method NAME[@SPLIT]=FILE`, provenance files), Table 1 / Table 2 with `--paper`, pass^k for
`--pass-k`, and the temporal and questions figures (`--plot-temporal`, `--plot-questions`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _fail(msg: str, code: int) -> None:
    print(f"adapt: {msg}", file=sys.stderr)
    raise SystemExit(code)


def ks(text: str) -> tuple:
    """`--pass-k 1,2,4`: distinct whole numbers >= 1, ascending."""
    try:
        values = sorted({int(x) for x in text.split(",") if x.strip()})
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a list of whole numbers like 1,2,4") from None
    if not values or values[0] < 1:
        raise argparse.ArgumentTypeError(f"'{text}': each k must be at least 1")
    return tuple(values)


def mapping(args) -> dict:
    """The `--method` mapping (FILE -> (method, split)); exit 2 on a malformed item."""
    from ..harness.methods import MethodError, parse_mapping

    try:
        return parse_mapping(args.method)
    except MethodError as exc:
        _fail(str(exc), 2)


def run_files(args, mapped: dict) -> list:
    """The results files to read: the positional ones, then the `--method` files not among them."""
    given = list(args.runs)
    known = {str(Path(p).resolve()) for p in given}
    given += [f for f in mapped if f not in known]
    if not given:
        _fail("give results files (adapt eval runs/*.jsonl) or --method NAME=FILE", 2)
    return given


def resolve(runs, mapped: dict, unseen) -> list:
    """The records relabelled with their method and the split they were evaluated on (`methods`); exit 1
    on an unreadable provenance file or a split the spec does not have."""
    from ..harness.methods import MethodError, Resolver

    resolver = Resolver(mapped)
    try:
        records = [resolver.resolve(r, src) for r, src in zip(runs.records, runs.sources, strict=True)]
    except MethodError as exc:
        _fail(str(exc), 1)
    splits = {r.split for r in records if r.split is not None}
    if splits:
        bad = sorted(splits - set(unseen()))
        if bad:
            _fail(f"split {', '.join(map(str, bad))} (from --method or a model's training.json) is not in the spec's "
                  f"splits.yaml (splits: {', '.join(map(str, unseen())) or 'none'})", 1)
    return records


def seed_notes(runs, resolved: list) -> list:
    """Warnings for episodes run on a scene seed their model was trained on (`harness.seeds`); `resolved`:
    the records relabelled with their methods, parallel to `runs.records`."""
    from ..harness.methods import MethodError, trained_seeds
    from ..harness.seeds import seen_seeds_lines

    trained: dict = {}
    for r, src in zip(runs.records, runs.sources, strict=True):
        model = (r.agent_config or {}).get("model")
        if isinstance(model, str) and model not in trained:
            try:
                trained[model] = trained_seeds(model, (str(Path(src).parent),) if src else ())
            except MethodError:
                trained[model] = ()
    return seen_seeds_lines(resolved, trained)


def with_ceiling(args, records: list) -> tuple:
    """(records, notes): with the oracle's ceiling row at the records' budget added when they have no
    teacher row (not for --by breakdowns, nor with --no-ceiling)."""
    from ..harness.ceiling import ceiling, needs_ceiling

    if args.by or args.no_ceiling or not needs_ceiling(records):
        return records, []
    from ..compiler import load_domain

    added, line = ceiling(records, load_domain(args.spec))
    return [*records, *added], [line]


def one_budget(args, records: list) -> None:
    """Exit 2 when the records ran at different step budgets, unless --allow-mixed."""
    from ..harness.evaluate import mixed_budgets

    line = mixed_budgets(records)
    if line and not args.allow_mixed:
        _fail(line, 2)


def tables(args, records: list, unseen) -> tuple:
    """(rows, text, csv thunk, markdown thunk, notes) of the paper layout."""
    from ..harness import papertables as pt
    from ..harness.evaluate import notes, table
    from ..harness.methods import mixed_models

    rows = table(records, unseen() if any(r.split is not None for r in records) else None, args.pass_k)
    lines = pt.notes(rows) + notes(rows) + mixed_models(records)
    return (rows, pt.render_text(rows, args.paper), lambda: pt.render_csv(rows),
            lambda: "\n\n".join([pt.render_markdown(rows, args.paper), *lines]), lines)


def paired_texts(args, records: list, unseen) -> tuple | None:
    """The `--paired METHOD` table as (text, Markdown), the pairing computed once; None without the option;
    exit 2 when no record is METHOD's."""
    if not args.paired:
        return None
    from ..harness import paired as pr

    methods = sorted({r.agent for r in records})
    if args.paired not in methods:
        _fail(f"--paired {args.paired}: no record of that method (methods here: {', '.join(methods)})", 2)
    rows = pr.paired(records, args.paired, unseen() if any(r.split is not None for r in records) else None)
    return pr.render_text(rows, args.paired), pr.render_markdown(rows, args.paired)


def figures(args, records: list) -> None:
    """Write the temporal and questions figures asked for."""
    from ..errors import AdaptError
    from ..harness import plots

    if not (args.plot_temporal or args.plot_questions):
        return
    plots.require()  # PlotsUnavailable before any replay
    try:
        if args.plot_temporal:
            plots.draw_temporal(_curves(args, records), Path(args.plot_temporal))
        if args.plot_questions:
            plots.draw_questions(records, Path(args.plot_questions))
    except AdaptError:
        raise  # PlotsUnavailable: the one handler prints it
    except (OSError, ValueError) as exc:
        _fail(f"cannot write the plot ({getattr(exc, 'strerror', None) or exc})", 1)


def _curves(args, records: list) -> dict:
    from ..compiler import load_domain
    from ..harness.temporal import replay_all

    replays = replay_all(records, load_domain(args.spec))
    if replays.skipped:
        print(f"adapt: {replays.skipped_text()}", file=sys.stderr)
    if not replays.curves:
        _fail("no episode could be replayed for the temporal figure (records of another spec? pass its --spec)", 1)
    return replays.curves


def add_options(p) -> None:
    """The paper options of `adapt eval`."""
    p.add_argument("--method", action="append", default=[], metavar="NAME[@SPLIT]=FILE",
                   help="every record in FILE is method NAME (e.g. reflection-dpo@1=runs/dpo1.jsonl: trained on "
                        "split 1); repeatable. Without it a record's method is its model's training.json method, "
                        "else its agent (docs/evaluation.md)")
    p.add_argument("--paper", action="store_true", help="print the paper's published numbers beside ours")
    p.add_argument("--paired", metavar="METHOD",
                   help="also compare every method with METHOD on the same episodes (split, persona, task, scene "
                        "seed): the mean per-episode satisfaction difference ± its standard error clustered by "
                        "scene, e.g. --paired planner for trained models against their base")
    p.add_argument("--pass-k", type=ks, metavar="K[,K...]",
                   help="the k of pass^k (default: 1 and the most scene seeds every method, persona and task has)")
    p.add_argument("--plot-temporal", metavar="PATH",
                   help="draw the paper's temporal figure (satisfaction over the interaction, per method; replays "
                        "the episodes in --spec)")
    p.add_argument("--plot-questions", metavar="PATH",
                   help="draw questions asked against applicable preferences, per method")
