"""`adapt serve-env` as a whole process on a free port, for the tests that talk to the real server."""

from __future__ import annotations

import http.client
import json
import os
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

from ..procs import free_port, stop

ROOT = Path(__file__).resolve().parents[2]


def request(port: int, method: str, path: str, body=None, headers: dict | None = None, timeout: float = 10) -> tuple:
    """(status, decoded JSON answer) of one request on a fresh connection; `body` bytes or a dict."""
    data = json.dumps(body).encode() if isinstance(body, dict) else body
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=timeout)
    try:
        conn.request(method, path, body=data, headers={"Content-Type": "application/json", **(headers or {})})
        r = conn.getresponse()
        raw = r.read()
    finally:
        conn.close()
    return r.status, json.loads(raw) if raw.startswith(b"{") else raw


@contextmanager
def serve_env(*args: str, spec: Path = ROOT / "spec"):
    """Run `adapt serve-env --port P ARGS` until the block ends; yields the port once /health answers."""
    port = free_port()
    log = tempfile.TemporaryFile()  # noqa: SIM115 - closed in the finally below
    proc = subprocess.Popen([sys.executable, "-m", "adaptbench.cli", "serve-env", "--spec", str(spec), "--port",
                             str(port), *args], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=log,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        deadline = time.monotonic() + 60
        while True:
            if proc.poll() is not None:
                log.seek(0)
                raise RuntimeError(f"adapt serve-env exited with {proc.returncode}: {log.read()[-2000:]!r}")
            try:
                request(port, "GET", "/health", timeout=2)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        yield port
    finally:
        stop(proc)
        log.close()
