"""Progress bars for long work (rollouts, solvability checks), drawn by tqdm.

On a terminal the bar redraws in place; when stderr is not a terminal (CI logs, `2> log`) each update
becomes one plain line, at most one per tenth of the work and per ten seconds, plus the last one.
"""

from __future__ import annotations

import sys

NON_TTY_SECONDS = 10.0


class _Lines:
    """The stream tqdm writes to when stderr is not a terminal: each redraw as one plain line."""

    def __init__(self, stream):
        self.stream = stream

    def write(self, text: str) -> None:
        """Write a redraw (carriage returns and padding dropped) as a line."""
        line = text.replace("\r", "").replace("\x1b[A", "").rstrip()
        if line:
            self.stream.write(line + "\n")

    def flush(self) -> None:
        """Flush the underlying stream."""
        self.stream.flush()


def progress_bar(total: int, label: str, enabled: bool = True, stream=None, unit: str = "ep"):
    """A tqdm bar over `total` items (`unit`: episodes by default) on stderr (`bar.update()`,
    `bar.set_postfix_str(note)`, `bar.close()`; also a context manager); disabled: it draws nothing."""
    from tqdm import tqdm

    stream = stream or sys.stderr
    tty = hasattr(stream, "isatty") and stream.isatty()
    if tty:
        return tqdm(total=total, desc=label, file=stream, unit=unit, dynamic_ncols=True, disable=not enabled)
    return tqdm(total=total, desc=label, file=_Lines(stream), unit=unit, ncols=100, disable=not enabled,
                mininterval=NON_TTY_SECONDS, miniters=max(1, total // 10), ascii=True)
