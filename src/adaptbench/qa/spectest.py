"""`adapt test`: what a researcher runs in CI on a spec — validate (with the linter), every trajectory fixture
next to the spec, and the oracle's solvability on a few seeds — as a list of checks with a verdict each."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class Check:
    """One line of the report: a check's name, whether it passed, a summary, and detail lines."""

    name: str
    ok: bool
    summary: str
    details: tuple = ()


@dataclass
class Report:
    """Every check run on one spec, and how long it took."""

    spec: str
    checks: list = field(default_factory=list)
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        """True when every check passed."""
        return all(c.ok for c in self.checks)

    def render(self, limit: int = 20) -> str:
        """The short text report (at most `limit` detail lines per check)."""
        lines = [f"adapt test {self.spec}"]
        for c in self.checks:
            lines.append(f"  {c.name:<9} {'ok' if c.ok else 'FAIL':<5} {c.summary}")
            lines += [f"      {d}" for d in c.details[:limit]]
            if len(c.details) > limit:
                lines.append(f"      ... and {len(c.details) - limit} more")
        failed = [c.name for c in self.checks if not c.ok]
        lines.append(f"FAIL: {', '.join(failed)} ({self.seconds:.1f} s)" if failed
                     else f"ok: {len(self.checks)} checks passed ({self.seconds:.1f} s)")
        return "\n".join(lines)


def run_tests(spec, fixtures=None, seeds=(0, 1), workers: int = 1, strict: bool = False,
              progress: bool = False, personas=None, tasks=None) -> Report:
    """Validate `spec`, run the fixtures under `fixtures` (default SPEC/fixtures) and the solvability check on
    `seeds` for `personas` x `tasks` (default: all). Fixtures and solvability are skipped when the spec does
    not compile; unknown persona or task ids fail the solvability check."""
    start = time.perf_counter()
    report = Report(str(spec))
    domain = _validate(report, spec, strict)
    if domain is not None:
        report.checks.append(fixture_check(domain, Path(fixtures) if fixtures else Path(spec) / "fixtures"))
        report.checks.append(solvable_check(domain, spec, list(seeds), workers, progress, personas, tasks))
    report.seconds = time.perf_counter() - start
    return report


def _validate(report: Report, spec, strict: bool):
    from ..compiler import compile_cached

    domain, diags = compile_cached([spec])
    errors = [d.render() for d in diags if d.severity == "error"]
    warnings = [d.render() for d in diags if d.severity != "error"]
    if domain is None:
        report.checks.append(Check("validate", False, f"{len(errors)} error(s)", tuple(errors + warnings)))
        return None
    counts = ", ".join(f"{v} {k}" for k, v in domain.counts().items())
    report.checks.append(Check("validate", True, f"{counts} (spec hash {domain.spec_hash})"))
    from ..compiler.lint import acknowledged

    known = [f"expected {code} on {pid}.{prid}: {why}" for pid, prid, code, why in acknowledged(domain)]
    report.checks.append(Check("lint", not (strict and warnings),
                               f"{len(warnings)} warning(s)" + (f", {len(known)} expected (expected_lint)" if known else "")
                               + (" (--strict: warnings fail)" if strict else ""), tuple(warnings + known)))
    return domain


def fixture_check(domain, root: Path) -> Check:
    """Run every fixture under `root`; a pending fixture must still fail (else its `pending:` is stale)."""
    from .fixtures import find_fixtures, run_fixture

    paths = find_fixtures(root)
    if not paths:
        return Check("fixtures", True, f"no fixtures under {root} (see docs/fixtures.md)")
    details, held, pending = [], 0, 0
    for path in paths:
        out = run_fixture(domain, path)
        if out.pending is not None and out.problems:
            pending += 1
        elif out.pending is not None:
            details.append(f"{path}: passes now: remove its `pending:` line")
        elif out.problems:
            details += [f"{path}: {p}" for p in out.problems]
        else:
            held += 1
    failed = len(paths) - held - pending
    summary = f"{held}/{len(paths)} hold" + (f", {pending} pending" if pending else "") + \
        (f", {failed} fail" if failed else "") + f" ({root})"
    return Check("fixtures", failed == 0, summary, tuple(details))


def solvable_check(domain, spec, seeds: list, workers: int, progress: bool, personas=None, tasks=None) -> Check:
    """The oracle on every persona x task x seed must satisfy every applicable preference."""
    from .solvable import unsolved

    personas = list(personas or domain.persona)
    tasks = list(tasks or domain.task)
    unknown = [f"unknown persona '{p}'" for p in personas if p not in domain.persona] + \
        [f"unknown task '{t}'" for t in tasks if t not in domain.task]
    if unknown:
        return Check("solvable", False, "; ".join(unknown))
    rows = unsolved(str(spec), personas, tasks, seeds, workers, progress=progress)
    grid = f"{len(personas)} personas x {len(tasks)} tasks x seeds {', '.join(map(str, seeds))}"
    details = tuple(f"{p}/{t} seed {s}: {pref}: {why}" for p, t, s, pref, why in rows)
    return Check("solvable", not rows, f"{len(rows)} applicable preference(s) the oracle cannot satisfy ({grid})",
                 details)
