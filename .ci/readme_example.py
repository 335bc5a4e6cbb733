"""Print the README's Python example (the first ```python block of its "From Python" section) or, with
--output, the ```text block that shows what it prints. CI runs the example in a fresh venv with only the
built wheel installed; tests/test_readme.py runs it against the checkout."""

import re
import sys
from pathlib import Path

README = Path(__file__).resolve().parent.parent / "README.md"


def blocks() -> tuple:
    """(code, expected output) of the README's Python example."""
    text = README.read_text(encoding="utf-8")
    section = text[text.index("From Python"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    output = re.search(r"```text\n(.*?)```", section, re.S).group(1)
    return code, output


if __name__ == "__main__":
    sys.stdout.write(blocks()[1 if "--output" in sys.argv else 0])
