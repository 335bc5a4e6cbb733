"""Headless Chromium (Debian's `chromium` package) for page tests: the DOM after scripts ran, the console
messages the page logged, a screenshot. Tests skip with the reason when no Chromium is installed."""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from html.parser import HTMLParser

# flags for a machine with no network: nothing tried in the background (refused connections otherwise)
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--enable-logging=stderr", "--v=0")
CONSOLE = re.compile(r":CONSOLE[:(]\d*\)?\] (.*)")


def browser() -> str | None:
    """The Chromium executable, or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


def run(url: str, *extra: str, timeout: float = 60) -> tuple:
    """(stdout, console messages) of one headless Chromium run on `url` (with --dump-dom: the DOM)."""
    with tempfile.TemporaryDirectory(prefix="adapt-chromium-") as profile:
        proc = subprocess.run([browser(), *FLAGS, f"--user-data-dir={profile}", *extra, url],
                              capture_output=True, text=True, timeout=timeout)
    return proc.stdout, CONSOLE.findall(proc.stderr)


class Elements(HTMLParser):
    """Every start tag of a document as (tag, attributes), and the text of each element with an id."""

    def __init__(self, html: str):
        super().__init__()
        self.tags: list = []
        self.text: dict = {}
        self._open: list = []
        self.feed(html)

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.tags.append((tag, attrs))
        if tag not in ("br", "meta", "link", "input", "img"):
            self._open.append((tag, attrs.get("id")))
            if attrs.get("id"):
                self.text[attrs["id"]] = ""

    def handle_endtag(self, tag):
        while self._open:
            if self._open.pop()[0] == tag:
                break

    def handle_data(self, data):
        for _, ident in self._open:
            if ident:
                self.text[ident] += data

    def with_class(self, name: str) -> list:
        """Attributes of every element whose class list holds `name`."""
        return [a for _, a in self.tags if name in (a.get("class") or "").split()]
