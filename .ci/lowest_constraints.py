"""Print pip constraints that pin every core dependency of pyproject.toml to its lower bound.

CI installs the core (with the dev extra) under them and runs the suite, so the lowest versions we allow
are tested as well as the newest ones the main install resolves to.
"""

import re
import sys
import tomllib
from pathlib import Path

pyproject = tomllib.loads((Path(__file__).resolve().parent.parent / "pyproject.toml").read_text())
for requirement in pyproject["project"]["dependencies"]:
    m = re.fullmatch(r"\s*([A-Za-z0-9_.-]+)\s*>=\s*([0-9][^,;\s]*)\s*", requirement)
    if not m:
        sys.exit(f"cannot read a lower bound from {requirement!r}: write core dependencies as 'name>=version'")
    print(f"{m.group(1)}=={m.group(2)}")
