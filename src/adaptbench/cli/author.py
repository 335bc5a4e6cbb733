"""Authoring commands: `adapt test` (a spec's CI check), `adapt new persona|task`, `adapt vocab` and
`adapt schema` (JSON Schemas with the spec's declared names, for editor completion)."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from .episode import add_spec_option


def _cmd_test(args) -> int:
    from ..qa.spectest import run_tests
    from .runs import _seeds

    def ids(text):
        return [x.strip() for x in text.split(",") if x.strip()] if text else None

    report = run_tests(args.spec_dir, args.fixtures, _seeds(args.seeds), args.workers, args.strict,
                       progress=args.progress, personas=ids(args.personas), tasks=ids(args.tasks))
    print(report.render(limit=10**6 if args.verbose else 20))
    return 0 if report.ok else 1


def _cmd_new(args) -> int:
    from ..authoring import add_to_splits, skeleton_path, skeleton_text
    from ..compiler import SpecError
    from ..paper import is_packaged

    try:
        path, text = skeleton_path(args.spec, args.kind, args.id), skeleton_text(args.spec, args.kind, args.id)
    except SpecError:
        raise  # a ValueError too: the one handler reports its diagnostics
    except ValueError as exc:
        print(f"adapt: {exc}", file=sys.stderr)
        return 2
    if args.stdout:
        sys.stdout.write(text)
        return 0
    if is_packaged(path):
        print(f"adapt: {args.spec} is the spec installed with adaptbench (read-only); copy it with "
              "`adapt spec export DIR` and pass --spec DIR", file=sys.stderr)
        return 2
    if path.exists():
        print(f"adapt: {path} already exists (choose another id, or --stdout to print the skeleton)", file=sys.stderr)
        return 1
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    print(f"wrote {path}")
    if args.kind == "persona":  # every file written or changed is named, one a line
        note = add_to_splits(args.spec, args.id)
        if note:
            print(note)
    print(f"next: fill in the TODOs, then `adapt validate {args.spec}`")
    return 0


def _cmd_vocab(args) -> int:
    from ..authoring import vocabulary
    from ..compiler import load_domain

    sections = vocabulary(load_domain(args.spec))
    wanted = [k for k in sections if getattr(args, k)] or list(sections)
    if args.json:
        print(json.dumps({k: dict(sections[k]) for k in wanted}, indent=2))
        return 0
    for k in wanted:
        print(f"{k}:")
        width = max((len(n) for n, _ in sections[k]), default=0)
        for name, what in sections[k]:
            print(f"  {name:<{width}}  {what}")
    return 0


def _cmd_schema(args) -> int:
    from ..authoring import schemas

    domain = None
    if args.spec and Path(args.spec).is_dir():
        from ..compiler import load_domain

        domain = load_domain(args.spec)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, data in schemas(domain).items():
        (out / name).write_text(json.dumps(data, indent=2) + "\n")
        print(out / name)
    return 0


def _cmd_spec_export(args) -> int:
    from ..paper import export_spec, shipped_spec

    try:
        files = export_spec(args.dir)
    except FileExistsError as exc:
        print(f"adapt: {exc} (choose a new directory)", file=sys.stderr)
        return 2
    print(f"copied the paper's spec ({len(files)} files) from {shipped_spec()} to {args.dir}; "
          f"check it with: adapt validate {args.dir}")
    return 0


def add_commands(sub) -> None:
    """Register test, new, vocab and schema."""
    from ..paper import default_spec
    p = sub.add_parser("test", help="a spec's CI check: validate, lint, fixtures, solvability; exit 0/1",
                       description="Validate SPEC_DIR (with the linter), run every trajectory fixture under "
                                   "SPEC_DIR/fixtures (or --fixtures; format in docs/fixtures.md) and check that "
                                   "the oracle satisfies every applicable preference on a few seeds. Prints a "
                                   "short report; exit 0 when every check passes, 1 otherwise.")
    from .argtypes import spec_dir

    p.add_argument("spec_dir", nargs="?", default=default_spec(), type=spec_dir, help="spec directory (default: the paper's spec shipped with adaptbench; $ADAPT_SPEC overrides)")
    p.add_argument("--fixtures", help="fixture file or directory (default: SPEC_DIR/fixtures)")
    p.add_argument("--seeds", default="0-1", help="scene seeds for the solvability check (default 0-1)")
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1),
                   help="parallel processes for the solvability check (default: 2, or 1 on one core)")
    p.add_argument("--personas", help="solvability check only for these personas (comma-separated; default all)")
    p.add_argument("--tasks", help="solvability check only on these tasks (comma-separated; default all)")
    p.add_argument("--strict", action="store_true", help="linter warnings fail too")
    p.add_argument("--progress", action="store_true", help="show the solvability check's progress")
    p.add_argument("--verbose", "-v", action="store_true", help="list every problem (default: 20 per check)")
    p.set_defaults(func=_cmd_test, spec=None)

    p = sub.add_parser("new", help="write a commented skeleton of a persona or a task that validates",
                       description="`adapt new persona ID` writes spec/personas/ID.yaml (and adds ID to the split with the "
                                   "fewest unseen personas in spec/splits.yaml); `adapt new task ID` "
                                   "writes spec/tasks/ID.yaml (a task and its component, a recipe to fill in). Both validate as "
                                   "written; fill in the TODOs.")
    p.add_argument("kind", choices=["persona", "task"], help="what to create")
    p.add_argument("id", help="its id (snake_case)")
    add_spec_option(p)
    p.add_argument("--stdout", action="store_true", help="print the skeleton instead of writing it")
    p.set_defaults(func=_cmd_new)

    p = sub.add_parser("spec", help="the paper's spec shipped with adaptbench: `adapt spec export DIR` copies it",
                       description="The paper's spec is installed with the package (the default of --spec; "
                                   "$ADAPT_SPEC overrides). `export` copies it to DIR as the start of a new domain.")
    ssub = p.add_subparsers(dest="spec_command", metavar="SUBCOMMAND", required=True)
    q = ssub.add_parser("export", help="copy the paper's spec to DIR (new or empty) to edit it",
                        description="Copy the paper's spec to DIR (which must be new or empty); edit it and pass "
                                    "--spec DIR (or set ADAPT_SPEC=DIR).")
    q.add_argument("dir", help="directory to create")
    q.set_defaults(func=_cmd_spec_export)

    p = sub.add_parser("vocab", help="list the names rules may use and what each matches",
                       description="The tags, categories, components (and groups) and styles of the spec, "
                                   "with what each matches in the catalogue.")
    add_spec_option(p)
    for k in ("tags", "categories", "components", "styles"):
        p.add_argument(f"--{k}", action="store_true", help=f"only the {k}")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_cmd_vocab)

    p = sub.add_parser("schema", aliases=["schemas"], help="write JSON Schemas of the spec files (for editors)",
                       description="Write *.schema.json for each kind of spec file, with field descriptions and "
                                   "the names --spec declares (tags, categories, locations, substances, "
                                   "components) so an editor completes them. Keep the output out of git "
                                   "(e.g. --out .schemas/ and `.schemas/` in .gitignore).")
    p.add_argument("--out", required=True, help="directory to write *.schema.json into, e.g. .schemas/")
    p.add_argument("--spec", default=default_spec(), help="spec whose names to list (default: the paper's spec; "
                   "$ADAPT_SPEC overrides; skipped if absent)")
    p.set_defaults(func=_cmd_schema)
