"""`adapt grammar build | check | show`: the committed grammars and the grammar of any state."""

from __future__ import annotations

import sys
from pathlib import Path

from .argtypes import read_lines, seed
from .episode import _domain, add_spec_option


def _expected(args):
    from ..grammars import build_index
    from ..grammars.files import expected_files

    domain = _domain(args)
    return expected_files(domain, build_index(domain))


def _cmd_build(args) -> int:
    from ..grammars.files import build

    for path in build(Path(args.out), _expected(args)):
        print(path)
    return 0


def _cmd_check(args) -> int:
    from ..grammars.files import drift

    problems = drift(Path(args.out), _expected(args))
    for path, what in problems:
        print(f"{path}: {what}", file=sys.stderr)
    if problems:
        print(f"{len(problems)} grammar file(s) drifted from spec/: run `adapt grammar build`", file=sys.stderr)
        return 1
    print(f"ok: the grammars in {args.out}/ match spec/")
    return 0


def _replay(args, domain):
    from ..runtime.env import Env

    env = Env(domain, args.task, seed=None if args.full_scene else args.seed, full_scene=args.full_scene)
    env.reset()
    if args.after:
        for text in read_lines(args.after):
            if env.done:
                break
            env.step(text)
    return env


def _cmd_show(args) -> int:
    from ..grammars import GrammarCache, build_index

    domain = _domain(args)
    if args.task not in domain.task:
        print(f"adapt: unknown task '{args.task}' (choose from: {', '.join(domain.task)})", file=sys.stderr)
        return 2
    env = _replay(args, domain)
    cache = GrammarCache(build_index(domain), {t.id: f"task {t.id}: {t.text}" for t in domain.tasks})
    sys.stdout.write(cache.state(args.task, env.observed(), args.level, args.variant).text)
    return 0


# grammars.LEVELS and grammars.VARIANTS, written out so that building the parser does not import the
# grammar code (and the compiler behind it); tests/grammars/test_cli_grammar.py checks they agree.
LEVELS = ("syntax", "observed", "typed")
VARIANTS = ("default", "never_ask", "ask_only")


def add_commands(sub) -> None:
    """Register `adapt grammar` and its subcommands."""
    g = sub.add_parser("grammar", help="build, check or show the action grammars",
                       description="The action grammars generated from spec/: `build` writes grammars/, "
                                   "`check` fails when they drift from spec/, `show` prints a state's grammar.")
    gsub = g.add_subparsers(dest="grammar_command", metavar="SUBCOMMAND", required=True)
    from ..paper import default_grammars

    for name, func, text in (("build", _cmd_build, "regenerate the committed grammars"),
                             ("check", _cmd_check, "exit 1 when the committed grammars differ from spec/")):
        p = gsub.add_parser(name, help=text, description=text)
        add_spec_option(p)
        p.add_argument("--out", default=default_grammars(),
                       help="grammar directory (default: the paper's grammars/, in a checkout the repository's)")
        p.set_defaults(func=func)
    p = gsub.add_parser("show", help="print the grammar of the state reached after some actions",
                        description="Replay ACTIONS_FILE (if given) in a scene of TASK and print the grammar "
                                    "of the state reached (what the agent may name there).")
    add_spec_option(p)
    p.add_argument("--task", required=True, help="task id, e.g. eggs")
    scene = p.add_mutually_exclusive_group(required=True)
    scene.add_argument("--seed", type=seed, help="scene seed")
    scene.add_argument("--full-scene", action="store_true", help="include every object")
    p.add_argument("--after", metavar="ACTIONS_FILE", help="actions to replay first (one per line, # comments)")
    p.add_argument("--level", choices=LEVELS, default="observed", help="syntax | observed (default) | typed")
    p.add_argument("--variant", choices=VARIANTS, default="default",
                   help="default | never_ask (no Ask) | ask_only (a forced question)")
    p.set_defaults(func=_cmd_show)
