"""Builds the paper's spec into the wheel: the repository's top-level `spec/` and `grammars/` (the one
copy, which authors edit) are copied to `adaptbench/data/` in the build, so an installed package finds
them (`adaptbench.paper`). An editable install reads them from the checkout instead."""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
SHIPPED = ("spec", "grammars")


class BuildWithSpec(build_py):
    """build_py, plus the paper's spec and grammars as package data."""

    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return
        for name in SHIPPED:
            dest = Path(self.build_lib) / "adaptbench" / "data" / name
            if dest.exists():
                shutil.rmtree(dest)
            shutil.copytree(ROOT / name, dest, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))


setup(cmdclass={"build_py": BuildWithSpec})
