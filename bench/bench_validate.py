"""Validating the full spec.

In-process: cold (parse, schema, rules, checks) and from the on-disk cache. Whole process, as a user runs
it (`adapt validate spec`: interpreter start, imports, hashing, output): warm (the compiled domain and its
warnings in the cache) and cold (an empty cache). `adapt --help` shows the floor of process start plus
argument parsing.

Compared with what a user would otherwise do: load the YAML with PyYAML's pure-Python SafeLoader
and validate it with jsonschema — no positions, no rule parsing, no semantic checks.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile

import yaml

from adaptbench.compiler import compile_spec, load_domain
from adaptbench.compiler.loader import schema, spec_files

from .common import ROOT, SPEC, report, timeit


def plain_yaml_and_schema() -> None:
    """The alternative: yaml.safe_load + jsonschema, nothing else."""
    import jsonschema

    for kind, path in spec_files([SPEC]):
        jsonschema.validate(yaml.load(path.read_text(), Loader=yaml.SafeLoader), schema(kind))


def adapt_process(args: list, cache: str, cwd=ROOT) -> None:
    """Run `adapt ARGS` as a fresh process (the installed entry point's module) with ADAPT_CACHE=cache."""
    env = {**os.environ, "ADAPT_CACHE": cache}
    r = subprocess.run([sys.executable, "-m", "adaptbench.cli", *args], cwd=cwd, env=env, capture_output=True)
    if r.returncode != 0:
        raise RuntimeError(f"adapt {' '.join(args)} exited {r.returncode}: {r.stderr.decode()[-500:]}")


def whole_process(n: int) -> tuple[float, float, float, float]:
    """(warm, edited, cold, --help) seconds of `adapt validate spec` as separate processes: warm = the spec is
    in the cache; edited = a persona file just changed (the cache holds other specs); cold = an empty cache."""
    import shutil

    with tempfile.TemporaryDirectory() as tmp:
        adapt_process(["validate", "spec"], tmp)
        warm = timeit(lambda: adapt_process(["validate", "spec"], tmp), repeat=n)
        helps = timeit(lambda: adapt_process(["--help"], tmp), repeat=n)
        work = os.path.join(tmp, "work")
        shutil.copytree(SPEC, os.path.join(work, "spec"), ignore=shutil.ignore_patterns("fixtures"))
        persona = os.path.join(work, "spec", "personas", "juan.yaml")
        edits = iter(range(10**6))

        def edited_run():
            with open(persona, "a") as f:
                f.write(f"# edit {next(edits)}\n")
            adapt_process(["validate", "spec"], tmp, cwd=work)

        edited = timeit(edited_run, repeat=n)

    def cold_run():
        with tempfile.TemporaryDirectory() as empty:
            adapt_process(["validate", "spec"], empty)

    return warm, edited, timeit(cold_run, repeat=max(3, n // 2)), helps


def adapt_test_spec() -> tuple[float, float]:
    """(wall, CPU) seconds of one `adapt test spec --workers 2` process (its checks' verdicts do not matter here)."""
    import resource
    import time

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([sys.executable, "-m", "adaptbench.cli", "test", "spec", "--workers", "2"], cwd=ROOT,
                       env={**os.environ, "ADAPT_CACHE": tmp}, capture_output=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def run(quick: bool = False) -> list:
    """Measure and return report rows."""
    n = 3 if quick else 7
    cold = timeit(lambda: compile_spec([SPEC]), repeat=n)
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["ADAPT_CACHE"] = tmp
        load_domain(SPEC)
        cached = timeit(lambda: load_domain(SPEC), repeat=n * 3)
        del os.environ["ADAPT_CACHE"]
    plain = timeit(plain_yaml_and_schema, repeat=n)
    warm_p, edited_p, cold_p, help_p = whole_process(n)
    rows = []
    if not quick:
        wall, cpu = adapt_test_spec()
        rows.append(("`adapt test spec` process, 2 workers", wall, "s", "< 60 s", f"{cpu:.1f} s of CPU in all"))
    return rows + [
        ("validate full spec, cold", cold, "s", "< 1 s", f"{plain / cold:.2f}x the speed of yaml+jsonschema alone ({plain:.3f} s)"),
        ("validate full spec, from cache", cached, "s", "< 0.1 s", f"{cold / cached:.0f}x faster than cold"),
        ("`adapt validate spec` process, warm cache", warm_p, "s", "< 0.5 s", f"process start included; `adapt --help` {help_p:.3f} s"),
        ("`adapt validate spec` process, spec just edited", edited_p, "s", "< 1 s", "compile; the rule parser's tables cached"),
        ("`adapt validate spec` process, cold cache", cold_p, "s", "< 1.5 s", "process start, compile, cache write"),
    ]


if __name__ == "__main__":
    report(run())
