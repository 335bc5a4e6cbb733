"""The scripts in bench/ as modules, for the tests of their functions."""

from __future__ import annotations

import functools
import importlib.util
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[2] / "bench"


@functools.cache
def bench_script(name: str):
    """bench/NAME.py loaded as a module (once), with bench/ on the import path while it loads so that it can
    import its neighbours."""
    sys.path.insert(0, str(BENCH))
    try:
        spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(BENCH))
    return module
