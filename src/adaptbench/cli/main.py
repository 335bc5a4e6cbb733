"""The `adapt` command: validate specs, inspect scenes, play and replay episodes.

Run `adapt --help` or `adapt COMMAND --help` for details.
"""

from __future__ import annotations

import argparse
import sys

EPILOG = """\
examples:
  adapt validate spec                       check every spec file, one line per problem
  adapt validate spec --format json         the same, as JSON for editors and CI
  adapt test spec                           validate, lint, run spec/fixtures/, check solvability
  adapt new persona zoe                     a commented persona skeleton that validates
  adapt vocab --tags                        the tags rules may use, and what each matches
  adapt schema --out .schemas/              JSON Schemas with the spec's names, for editor completion
  adapt scene --seed 3 --json               the sampled scene for seed 3
  adapt play --task eggs --persona juan     play an episode in the terminal
  adapt replay --task eggs --persona juan --full-scene actions.txt --json
  adapt view runs/demo.jsonl --out report.html   the episodes as one HTML page
  adapt probe answers --model student       does the model's next action follow the user's answer?
  adapt probe tasks --model student         does its first action follow the task?
"""


def _cmd_validate(args) -> int:
    from ..compiler import compile_cached
    from ..compiler.diagnostics import render_all

    domain, diags = compile_cached(args.spec_dirs)
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
        from ..compiler.lint import render_matrix

        print(render_matrix(domain))
    if args.format == "text":
        counts = ", ".join(f"{v} {k}" for k, v in domain.counts().items())
        print(f"ok: {counts} (spec hash {domain.spec_hash})")
    return 0


def _add_validate(sub) -> None:
    p = sub.add_parser("validate", help="check spec files and report every problem with file:line:col",
                       description="Compile the spec directories and report every problem at once. "
                                   "Exit 0 when clean, 1 on errors, 2 on usage errors.")
    from ..paper import default_spec
    from .argtypes import spec_dir

    p.add_argument("spec_dirs", nargs="*", default=[default_spec()], type=spec_dir,
                   help="spec directories (default: the paper's spec shipped with adaptbench; $ADAPT_SPEC overrides)")
    p.add_argument("--format", choices=["text", "json"], default="text", help="output format")
    p.add_argument("--matrix", action="store_true",
                   help="also print how many preferences of each persona apply to each task")
    p.set_defaults(func=_cmd_validate)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser for `adapt` and all subcommands."""
    parser = argparse.ArgumentParser(
        prog="adapt", description="ADAPT as data: validate specs, run the household simulator, "
        "evaluate preference satisfaction.", epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    _add_validate(sub)
    from . import author, episode, grammar, probe, runs, serve_env, train, train_grpo, view

    author.add_commands(sub)
    episode.add_commands(sub)
    runs.add_commands(sub)
    grammar.add_commands(sub)
    view.add_commands(sub)
    probe.add_commands(sub)
    serve_env.add_commands(sub)
    train.add_commands(sub)  # owns the `train` group
    train_grpo.add_commands(sub)  # after any module that registers the `train` group
    return parser


def report_spec_error(exc, spec=None) -> None:
    """The one report every command gives on a spec that does not compile: each located diagnostic, then a
    count, on stderr (the command then exits 1)."""
    from ..compiler.diagnostics import render_all

    errors = sum(d.severity == "error" for d in exc.diagnostics)
    print(render_all(exc.diagnostics), file=sys.stderr)
    where = f" in {spec}" if isinstance(spec, str) else ""
    print(f"adapt: {errors} error(s){where}; fix them and run again (`adapt validate` lists them)", file=sys.stderr)


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
    except KeyboardInterrupt:  # Ctrl-C where no command caught it (a model loading, a spec compiling)
        print("\nadapt: interrupted (Ctrl-C) before the command finished", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0
    except Exception as exc:  # noqa: BLE001 - the one place that turns expected failures into messages
        return _report(exc, getattr(args, "spec", None))


def _report(exc: Exception, spec=None) -> int:
    """Print an `AdaptError` (a spec error's diagnostics, or its one-line message) or a file problem as a
    message, with its exit code; anything else is a bug and keeps its traceback."""
    from ..compiler import SpecError
    from ..errors import AdaptError

    if isinstance(exc, SpecError):
        report_spec_error(exc, spec)
        return exc.exit_code
    if isinstance(exc, AdaptError):
        print(f"adapt: {exc}", file=sys.stderr)
        return exc.exit_code
    if isinstance(exc, OSError) and exc.filename:
        print(f"adapt: {exc.filename}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    if isinstance(exc, UnicodeDecodeError):
        print(f"adapt: a file is not UTF-8 text ({exc.reason} at byte {exc.start})", file=sys.stderr)
        return 1
    raise exc

