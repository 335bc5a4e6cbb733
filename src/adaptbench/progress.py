"""A dependency-free progress bar for long work (rollouts, training)."""

from __future__ import annotations

import sys
import time


class Progress:
    """`with Progress(total, "rollouts") as bar: bar.update()` — draws on stderr when it is a terminal,
    else prints a line every 10%."""

    def __init__(self, total: int, label: str, stream=None):
        self.total, self.label, self.done = max(total, 0), label, 0
        self.stream = stream or sys.stderr
        self.start = time.perf_counter()
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self._last_decile = -1

    def __enter__(self):
        self._draw()
        return self

    def __exit__(self, *exc):
        self._draw(final=True)

    def update(self, n: int = 1, note: str = "") -> None:
        """Advance by n."""
        self.done += n
        self._draw(note=note)

    def _draw(self, final: bool = False, note: str = "") -> None:
        elapsed = time.perf_counter() - self.start
        frac = self.done / self.total if self.total else 1.0
        rate = self.done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - self.done) / rate if rate > 0 else 0.0
        bar = "#" * int(frac * 30)
        line = f"{self.label}: [{bar:<30}] {self.done}/{self.total} {rate:.1f}/s eta {eta:.0f}s {note}"
        if self.tty:
            self.stream.write("\r" + line[:120].ljust(120) + ("\n" if final else ""))
        elif final or int(frac * 10) > self._last_decile:
            self._last_decile = int(frac * 10)
            self.stream.write(line + "\n")
        self.stream.flush()
