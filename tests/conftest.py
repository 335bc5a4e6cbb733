"""Shared fixtures: the compiled shipped spec, and golden-file handling."""

from __future__ import annotations

from pathlib import Path

import pytest

from adaptbench.compiler import load_domain

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "spec"


def pytest_addoption(parser):
    parser.addoption("--update-golden", action="store_true", help="rewrite golden/snapshot files")


@pytest.fixture(scope="session")
def domain():
    return load_domain(SPEC, use_cache=False)


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
