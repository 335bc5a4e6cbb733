"""Validating the full spec: cold (parse, schema, rules, checks) and from the on-disk cache.

Compared with what a user would otherwise do: load the YAML with PyYAML's pure-Python SafeLoader
and validate it with jsonschema — no positions, no rule parsing, no semantic checks.
"""

from __future__ import annotations

import os
import tempfile

import yaml

from adaptbench.compiler import compile_spec, load_domain
from adaptbench.compiler.loader import schema, spec_files

from .common import SPEC, report, timeit


def plain_yaml_and_schema() -> None:
    """The alternative: yaml.safe_load + jsonschema, nothing else."""
    import jsonschema

    for kind, path in spec_files([SPEC]):
        jsonschema.validate(yaml.load(path.read_text(), Loader=yaml.SafeLoader), schema(kind))


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
    return [
        ("validate full spec, cold", cold, "s", "< 1 s", f"{plain / cold:.2f}x the speed of yaml+jsonschema alone ({plain:.3f} s)"),
        ("validate full spec, from cache", cached, "s", "< 0.1 s", f"{cold / cached:.0f}x faster than cold"),
    ]


if __name__ == "__main__":
    report(run())
