"""Trajectory fixtures: hand-written episodes with the verdicts each preference must get.

A fixture is one YAML file (format in docs/fixtures.md):

    persona: juan
    task: eggs
    scene: full                # or `seed: 3` (a sampled scene)
    actions: [Look for eggs, ...]
    expect: {preference_id: satisfied | violated | inapplicable}
    mutations:                 # optional: edit the actions, and the verdicts must change as said
      - remove: "Pour whole_milk from milk_0 to pan_1"
        expect: {whole_milk_in_eggs: violated}
      - replace: ["old action", "new action"]
        expect: {...}
      - swap: ["action a", "action b"]
        expect: {...}

Adversarial fixtures ("tricks") add `trick:` (what a loophole-hunting policy tries), `why:` (what the
persona's sentence means at the table) and optionally `pending:` (the engine does not yet give the right
verdict: reported as an expected failure, and as a problem once it passes).

`check_fixture` returns the problems found, as sentences; an empty list means the fixture holds.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import AdaptError

VERDICTS = ("satisfied", "violated", "inapplicable")
KEYS = {"persona", "task", "scene", "seed", "actions", "expect", "mutations", "trick", "why", "pending"}
MUTATIONS = ("remove", "replace", "swap")


class FixtureError(AdaptError, ValueError):
    """A fixture file that cannot be read or does not have the fixture format."""


@dataclass(frozen=True)
class Outcome:
    """What one fixture gave: its problems (empty when it holds) and whether it is marked pending."""

    path: Path
    problems: tuple
    pending: str | None = None

    @property
    def ok(self) -> bool:
        """True when the fixture holds (a pending fixture holds when it still fails)."""
        return not self.problems if self.pending is None else bool(self.problems)


def find_fixtures(root) -> list[Path]:
    """Every fixture file (*.yaml, *.yml) under `root`, sorted; [] when `root` does not exist."""
    root = Path(root)
    if root.is_file():
        return [root]
    return sorted(p for p in root.rglob("*.y*ml") if p.is_file()) if root.is_dir() else []


def load_fixture(path) -> dict:
    """Read one fixture and check its shape; FixtureError says what is wrong."""
    import yaml

    path = Path(path)
    try:
        fx = yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise FixtureError(f"{path}: cannot read ({exc})") from None
    except yaml.YAMLError as exc:
        raise FixtureError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
    problems = shape_problems(fx)
    if problems:
        raise FixtureError(f"{path}: " + "; ".join(problems))
    return fx


def shape_problems(fx) -> list:
    """What keeps `fx` from being a fixture: missing or unknown keys, bad verdicts, bad mutations."""
    if not isinstance(fx, dict):
        return ["a fixture is a mapping with persona, task, actions and expect"]
    out = [f"missing '{k}'" for k in ("persona", "task", "actions", "expect") if k not in fx]
    out += [f"unknown key '{k}' (keys: {', '.join(sorted(KEYS))})" for k in fx if k not in KEYS]
    if "actions" in fx and not (isinstance(fx["actions"], list) and all(isinstance(a, str) for a in fx["actions"])):
        out.append("'actions' must be a list of action lines")
    if fx.get("scene", "full") not in ("full", "sampled"):
        out.append("'scene' is full or sampled (a sampled scene needs `seed:`)")
    if fx.get("scene") == "sampled" and "seed" not in fx:
        out.append("a sampled scene needs `seed:`")
    out += _expect_problems(fx.get("expect", {}), "expect")
    for k, m in enumerate(fx.get("mutations") or ()):
        out += _mutation_problems(m, f"mutation {k + 1}")
    return out


def _expect_problems(expect, where: str) -> list:
    if not isinstance(expect, dict) or not expect:
        return [f"'{where}' maps preference ids to {' | '.join(VERDICTS)}"]
    return [f"{where}: {p} must be {' | '.join(VERDICTS)}, not {v!r}" for p, v in expect.items() if v not in VERDICTS]


def _mutation_problems(m, where: str) -> list:
    if not isinstance(m, dict):
        return [f"{where} is a mapping with one of {', '.join(MUTATIONS)} and expect"]
    kinds = [k for k in MUTATIONS if k in m]
    out = [] if len(kinds) == 1 else [f"{where} needs exactly one of {', '.join(MUTATIONS)}"]
    for k in kinds:
        ok = isinstance(m[k], str) if k == "remove" else isinstance(m[k], list) and len(m[k]) == 2
        if not ok:
            out.append(f"{where}: '{k}' takes " + ("one action line" if k == "remove" else "two action lines"))
    return out + _expect_problems(m.get("expect"), f"{where} expect")


def mutate(actions: list, m: dict) -> list:
    """Apply one mutation (remove / replace / swap) to an action list; ValueError names a missing line."""
    out = list(actions)
    lines = [m["remove"]] if "remove" in m else list(m.get("replace", [])[:1]) + list(m.get("swap", []))
    for line in lines:
        if line not in out:
            raise ValueError(f"'{line}' is not one of the actions")
    if "remove" in m:
        out.remove(m["remove"])
    elif "replace" in m:
        old, new = m["replace"]
        out[out.index(old)] = new
    elif "swap" in m:
        a, b = m["swap"]
        i, j = out.index(a), out.index(b)
        out[i], out[j] = out[j], out[i]
    return out


def play(domain, fx: dict, actions: list) -> tuple[dict, list]:
    """Replay `actions` in the fixture's scene: ({preference id: Verdict}, problems of failed actions)."""
    from ..runtime.env import Env

    full = fx.get("scene", "full" if "seed" not in fx else "sampled") == "full"
    env = Env(domain, task=fx["task"], persona=fx["persona"], seed=fx.get("seed"), full_scene=full)
    env.reset()
    failed = []
    for action in actions:
        r = env.step(action)
        if not r.ok:
            failed.append(f"'{action}' failed: {r.observation}")
    return {v.id: v for v in env.evaluate().verdicts}, failed


def compare(verdicts: dict, expect: dict) -> list:
    """A sentence for every expected verdict the episode did not give."""
    out = []
    for pref, want in expect.items():
        if pref not in verdicts:
            out.append(f"unknown preference {pref} (the persona has: {', '.join(verdicts)})")
        elif verdicts[pref].verdict != want:
            out.append(f"{pref} is {verdicts[pref].verdict}, expected {want}: {verdicts[pref].reason}")
    return out


def check_fixture(domain, fx: dict) -> list:
    """Every problem of a loaded fixture on `domain`: unknown ids, failed actions, verdicts not as expected,
    in the original episode and in each mutation (prefixed `mutation N:`)."""
    unknown = [f"unknown {what} '{fx[what]}'" for what, pool in (("persona", domain.persona), ("task", domain.task))
               if fx[what] not in pool]
    if unknown:
        return unknown
    verdicts, failed = play(domain, fx, fx["actions"])
    out = failed + compare(verdicts, fx["expect"])
    for k, m in enumerate(fx.get("mutations") or ()):
        try:
            actions = mutate(fx["actions"], m)
        except ValueError as exc:
            out.append(f"mutation {k + 1}: {exc}")
            continue
        verdicts, failed = play(domain, fx, actions)
        out += [f"mutation {k + 1}: {p}" for p in failed + compare(verdicts, m["expect"])]
    return out


def run_fixture(domain, path) -> Outcome:
    """Load and check one fixture file."""
    try:
        fx = load_fixture(path)
    except FixtureError as exc:
        return Outcome(Path(path), (str(exc),))
    return Outcome(Path(path), tuple(check_fixture(domain, fx)), fx.get("pending"))


def coverage(paths) -> dict:
    """(persona, preference) -> the set of verdicts the fixtures at `paths` expect for it (their own
    episodes; mutations are checks of the verifier, not coverage)."""
    seen: dict = {}
    for path in paths:
        try:
            fx = load_fixture(path)
        except FixtureError:
            continue
        for pref, want in fx["expect"].items():
            seen.setdefault((fx["persona"], pref), set()).add(want)
    return seen
