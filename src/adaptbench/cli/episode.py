"""`adapt scene`, `adapt play` and `adapt replay`: episodes from the command line."""

from __future__ import annotations

import json
import sys

from .argtypes import positive, read_lines, seed


def _domain(args):
    """The compiled domain of `--spec`; a SpecError goes to the CLI's one handler (located diagnostics, exit 1)."""
    from ..compiler import load_domain

    return load_domain(args.spec)


def _env(args, domain):
    from ..agents.users import OfflineUser
    from ..runtime.env import Env

    for name, pool in (("task", domain.task), ("persona", domain.persona)):
        value = getattr(args, name)
        if value not in pool:
            print(f"adapt: unknown {name} '{value}' (choose from: {', '.join(pool)})", file=sys.stderr)
            raise SystemExit(2)
    user = OfflineUser(domain, domain.persona[args.persona], domain.task[args.task])
    seed = None if getattr(args, "full_scene", False) else args.seed
    return Env(domain, task=args.task, persona=args.persona, seed=seed,
               full_scene=getattr(args, "full_scene", False), user=user, max_steps=args.max_steps)


def format_verdicts(evaluation) -> str:
    """The verdict table printed at the end of an episode."""
    rows = [(v.verdict.upper(), v.id, v.reason) for v in evaluation.verdicts]
    width = max((len(r[1]) for r in rows), default=10)
    lines = [f"{'verdict':<13} {'preference':<{width}}  reason"]
    lines += [f"{a:<13} {b:<{width}}  {c}" for a, b, c in rows]
    rate = evaluation.satisfaction_rate
    lines.append(f"satisfied {evaluation.satisfied}, violated {evaluation.violated}, "
                 f"rate {'n/a' if rate is None else f'{rate:.1%}'}, questions {evaluation.questions}, "
                 f"completed: {', '.join(evaluation.completed) or 'nothing'}")
    return "\n".join(lines)


def _cmd_scene(args) -> int:
    from ..runtime.scene import sample_scene

    domain = _domain(args)
    scene = sample_scene(domain, None if args.full else args.seed, args.full)
    data = scene.as_dict(domain)
    if args.json:
        print(json.dumps(data, indent=2))
    else:
        print(f"{data['scene_id']}: {data['counts']['entities']} entities, {data['counts']['movables']} movables")
        for o in data["objects"]:
            print(f"  {o['id']:<28} in/on {o['location']}")
    return 0


def _cmd_replay(args) -> int:
    domain = _domain(args)
    actions = read_lines(args.actions)
    env = _env(args, domain)
    env.reset()
    steps = []
    for text in actions:
        if env.done:
            break
        r = env.step(text)
        steps.append({"action": text, "ok": r.ok, "observation": r.observation, "reply": r.reply})
        if not args.json:
            _print_step(len(steps), text, r)
    ev = env.evaluate()
    if args.json:
        out = {"task": args.task, "persona": args.persona, "scene": env.scene.scene_id, "steps": steps}
        out.update(ev.as_dict())
        print(json.dumps(out, indent=2))
    else:
        print(format_verdicts(ev))
    return 0


def _print_step(n: int, text: str, r) -> None:
    mark = "ok " if r.ok else "ERR"
    print(f"[{n:>2}] {mark} {text}")
    if r.observation:
        print(f"       {r.observation}")
    if r.reply:
        print(f"       user: {r.reply}")


def _cmd_play(args) -> int:
    domain = _domain(args)
    env = _env(args, domain)
    task = domain.task[args.task]
    print(f"Task: {task.text}   (persona hidden; type actions, 'help' for the action list, Ctrl-D to stop)")
    print("You are in a house with this layout:")
    print(env.reset())
    while not env.done:
        try:
            text = input("> ").strip()
        except EOFError:
            print()
            break
        if text in ("help", "?"):
            for a in domain.actions:
                print(f"  {' | '.join(a.forms):<60} e.g. {a.example}")
            continue
        if text:
            _play_line(domain, env, text)
    print(format_verdicts(env.evaluate()))
    return 0


def _play_line(domain, env, text: str) -> None:
    """One typed line: the verb in any case; a line that is no action uses no step and names the nearest one."""
    from .typed import fix_case, suggest

    fixed = fix_case(domain, text)
    if env.index.parser.parse(fixed) is None:
        near = suggest(domain, env.world, text)
        hint = f"did you mean '{near}'? " if near else ""
        print(f"       not an action (no step used): {hint}type 'help' for the action forms")
        return
    if fixed != text:
        print(f"       (read as '{fixed}')")
    _print_step(env.world.step + 1, fixed, env.step(fixed))


def add_spec_option(p) -> None:
    """The `--spec DIR` option every command that loads the domain takes."""
    from ..paper import default_spec
    from .argtypes import spec_dir

    p.add_argument("--spec", default=default_spec(), type=spec_dir, help="spec directory (default: the paper's spec shipped with adaptbench; $ADAPT_SPEC overrides)")


def _common(p) -> None:
    add_spec_option(p)
    p.add_argument("--task", required=True, help="task id, e.g. eggs, toast_coffee")
    p.add_argument("--persona", required=True, help="persona id, e.g. juan, ron")
    p.add_argument("--max-steps", type=positive, default=50, help="step limit (default 50)")


def add_commands(sub) -> None:
    """Register scene, play and replay."""
    p = sub.add_parser("scene", help="sample a scene and list its objects",
                       description="Sample the scene for a seed (every room, furniture and mandatory object; "
                                   "other movables with p=0.7) and print it.")
    add_spec_option(p)
    p.add_argument("--seed", type=seed, default=0, help="scene seed (default 0)")
    p.add_argument("--full", action="store_true", help="include every object")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_cmd_scene)

    p = sub.add_parser("play", help="play an episode in the terminal",
                       description="Type actions (e.g. 'Look for eggs', 'Ask \"How do you like your eggs?\"'); "
                                   "'Declare Done' ends the episode and prints the verdicts. The first words may be "
                                   "in any case; a line that is no action uses no step and names the nearest one "
                                   "(an action that fails, e.g. a precondition, uses a step, as in rollouts).")
    _common(p)
    p.add_argument("--seed", type=seed, default=0, help="scene seed (default 0)")
    p.add_argument("--full-scene", action="store_true", help="include every object")
    p.set_defaults(func=_cmd_play)

    p = sub.add_parser("replay", help="replay a file of actions and print verdicts",
                       description="Replay ACTIONS_FILE (one action per line, # comments; '-' for stdin) and "
                                   "print every step and the preference verdicts.")
    _common(p)
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--seed", type=seed, help="scene seed")
    g.add_argument("--full-scene", action="store_true", help="include every object")
    p.add_argument("actions", metavar="ACTIONS_FILE", help="file with one action per line")
    p.add_argument("--json", action="store_true", help="print JSON: steps, preferences, satisfaction_rate, questions")
    p.set_defaults(func=_cmd_replay)
