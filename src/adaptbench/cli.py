"""The `adapt` command: validate specs, inspect scenes, play and replay episodes.

Run `adapt --help` or `adapt COMMAND --help` for details.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

EPILOG = """\
examples:
  adapt validate spec                       check every spec file, one line per problem
  adapt validate spec --format json         the same, as JSON for editors and CI
  adapt schema --out schemas/               write the JSON Schemas for editor completion
  adapt scene --seed 3 --json               the sampled scene for seed 3
  adapt play --task eggs --persona juan     play an episode in the terminal
  adapt replay --task eggs --persona juan --full-scene actions.txt --json
"""


def _cmd_validate(args) -> int:
    from .compiler import compile_spec
    from .compiler.diagnostics import render_all

    domain, diags = compile_spec(args.spec_dirs)
    if args.format == "json":
        print(render_all(diags, "json"))
    elif diags:
        print(render_all(diags), file=sys.stderr if domain is None else sys.stdout)
    if domain is None:
        n = sum(d.severity == "error" for d in diags)
        if args.format == "text":
            print(f"{n} error(s)", file=sys.stderr)
        return 1
    if args.matrix:
        from .compiler.lint import render_matrix

        print(render_matrix(domain))
    if args.format == "text":
        counts = ", ".join(f"{v} {k}" for k, v in domain.counts().items())
        print(f"ok: {counts} (spec hash {domain.spec_hash})")
    return 0


def _cmd_schema(args) -> int:
    from .compiler.loader import SCHEMA_KINDS, schema

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for kind in SCHEMA_KINDS:
        (out / f"{kind}.schema.json").write_text(json.dumps(schema(kind), indent=2) + "\n")
        print(out / f"{kind}.schema.json")
    return 0


def _add_validate(sub) -> None:
    p = sub.add_parser("validate", help="check spec files and report every problem with file:line:col",
                       description="Compile the spec directories and report every problem at once. "
                                   "Exit 0 when clean, 1 on errors, 2 on usage errors.")
    p.add_argument("spec_dirs", nargs="*", default=["spec"], help="spec directories (default: spec)")
    p.add_argument("--format", choices=["text", "json"], default="text", help="output format")
    p.add_argument("--matrix", action="store_true",
                   help="also print how many preferences of each persona apply to each task")
    p.set_defaults(func=_cmd_validate)


def _add_schema(sub) -> None:
    p = sub.add_parser("schema", help="write the JSON Schemas of the spec files (for editors)")
    p.add_argument("--out", required=True, help="directory to write *.schema.json into")
    p.set_defaults(func=_cmd_schema)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser for `adapt` and all subcommands."""
    parser = argparse.ArgumentParser(
        prog="adapt", description="ADAPT as data: validate specs, run the household simulator, "
        "evaluate preference satisfaction.", epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    _add_validate(sub)
    _add_schema(sub)
    from . import cli_episode, cli_grammar, cli_runs

    cli_episode.add_commands(sub)
    cli_runs.add_commands(sub)
    cli_grammar.add_commands(sub)
    return parser


def main(argv=None) -> int:
    """Entry point of the `adapt` command."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return args.func(args)
    except SystemExit as exc:  # commands exit 1/2 with a message already printed
        return exc.code if isinstance(exc.code, int) else 1
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        return 0
    except Exception as exc:  # noqa: BLE001 - the one place that turns expected failures into messages
        return _report(exc)


def _report(exc: Exception) -> int:
    """Print a spec error's diagnostics or a file problem as a message; anything else is a bug and keeps
    its traceback."""
    from .compiler import SpecError

    if isinstance(exc, SpecError):
        print(str(exc), file=sys.stderr)
        print("the spec has errors: run `adapt validate` for details", file=sys.stderr)
        return 1
    if isinstance(exc, OSError) and exc.filename:
        print(f"adapt: {exc.filename}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    if isinstance(exc, UnicodeDecodeError):
        print(f"adapt: a file is not UTF-8 text ({exc.reason} at byte {exc.start})", file=sys.stderr)
        return 1
    raise exc


if __name__ == "__main__":
    sys.exit(main())
