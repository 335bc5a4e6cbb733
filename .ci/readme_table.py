"""README command 1 prints the README's results table: compare the Table 1 that `adapt eval ... --markdown`
prints (stdin) with the table under "Scripted agents on all 16 personas" in README.md; exit 1 with both
when they differ.

    adapt eval runs/demo.jsonl --markdown | python .ci/readme_table.py
"""

from __future__ import annotations

import sys
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"
MARKER = "Scripted agents on all 16 personas"


def first_table(lines: list) -> list:
    """The first run of consecutive lines that start with `|`."""
    out = []
    for line in lines:
        if line.startswith("|"):
            out.append(line.rstrip())
        elif out:
            break
    return out


def readme_table() -> list:
    """The README's results table (the one after MARKER)."""
    text = README.read_text(encoding="utf-8")
    return first_table(text[text.index(MARKER):].splitlines())


def main() -> int:
    """Compare; 0 when the tables are the same."""
    printed, shown = first_table(sys.stdin.read().splitlines()), readme_table()
    if printed == shown:
        print(f"README table: the {len(shown) - 2} rows command 1 prints")
        return 0
    print("README.md's table differs from what command 1 prints:", *shown, "printed:", *printed, sep="\n",
          file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
