"""Shared fixtures: the compiled shipped spec (`domain`), the small test spec (`small_domain`), and
golden-file handling.

Tests of the shipped paper spec are marked `paper` (automatically: every test that uses `domain`, or whose
module's SPEC is spec/): `pytest -m "not paper and not slow"` runs the engine tests alone, on tests/spec_small and on
specs the tests write, so an extension of spec/ can only break the `paper` tests about it."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from adaptbench.compiler import load_domain

# Every test searches the oracle's plans itself (tests time and interrupt rollouts, and change domains in
# memory); tests/agents/test_plan_cache.py turns the cache on where it tests it. Child processes inherit this.
os.environ.setdefault("ADAPT_ORACLE_CACHE", "0")

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "spec"
SMALL = ROOT / "tests" / "spec_small"


def _uses_shipped_domain(item) -> bool:
    """True when the test's `domain` is this file's (a module may override it with the small spec's)."""
    info = getattr(item, "_fixtureinfo", None)
    defs = info.name2fixturedefs.get("domain", ()) if info else ()
    return bool(defs) and defs[-1].baseid in ("", "tests")


def pytest_collection_modifyitems(config, items):
    for item in items:
        if _uses_shipped_domain(item) or getattr(getattr(item, "module", None), "SPEC", None) == SPEC:
            item.add_marker(pytest.mark.paper)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_auto_num_workers(config):
    """`-n auto`: one worker per core this process may run on (its CPU affinity and a cgroup CPU quota, which
    psutil's count of the host's cores misses in a container), at most one per 3 GiB of memory (a worker
    that loads a model peaks at 1-2 GiB). PYTEST_XDIST_AUTO_NUM_WORKERS=N still sets N."""
    import os

    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS", "").isdigit():
        return int(os.environ["PYTEST_XDIST_AUTO_NUM_WORKERS"])
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    try:  # cgroup v2: "max 100000" or "200000 100000" (quota, period)
        quota, period = Path("/sys/fs/cgroup/cpu.max").read_text().split()
        if quota != "max":
            cores = min(cores, max(1, int(quota) // int(period)))
    except (OSError, ValueError):
        pass
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
        cores = min(cores, max(1, memory // (3 << 30)))
    except (AttributeError, ValueError, OSError):
        pass
    return max(1, cores)


def pytest_addoption(parser):
    parser.addoption("--update-golden", action="store_true", help="rewrite golden/snapshot files")


@pytest.fixture(scope="session")
def domain():
    return load_domain(SPEC, use_cache=False)


@pytest.fixture(scope="session")
def small_domain():
    return load_domain(SMALL, use_cache=False)


@pytest.fixture
def golden(request):
    """Compare text with a golden file; `pytest --update-golden` rewrites it."""
    update = request.config.getoption("--update-golden")

    def check(path: Path, text: str) -> None:
        if update or not path.exists():
            if not update:
                pytest.fail(f"missing golden file {path}: run pytest --update-golden")
            path.write_text(text)
            return
        assert text == path.read_text(), f"{path} differs (pytest --update-golden to accept)"
    return check


@pytest.fixture
def cereal_steps_raise(monkeypatch):
    """Every step of a cereal episode raises RuntimeError("boom") (the other tasks step normally): for
    tests that one episode's failure becomes its own error and spares the rest."""
    from adaptbench.runtime.env import Env

    real = Env.step

    def step(self, text):
        if self.task.id == "cereal":
            raise RuntimeError("boom")
        return real(self, text)

    monkeypatch.setattr(Env, "step", step)
