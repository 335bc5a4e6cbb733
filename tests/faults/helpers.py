"""Running the `adapt` command in a subprocess with time and memory limits."""

from __future__ import annotations

import os
import resource
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SPEC = ROOT / "spec"
MEMORY = 1 << 30  # 1 GiB of address space is plenty for any command on a hostile spec


def sigint_as_in_a_terminal() -> None:
    """A child's SIGINT as a terminal's foreground job has it (preexec_fn): the default handler. A shell
    starts a background job (`cmd &`, a CI step run that way) with SIGINT ignored, every descendant inherits
    that, and Python then installs no KeyboardInterrupt handler, so a Ctrl-C test would test nothing."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _limits(memory: int):
    def apply():
        resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
        os.setsid()
    return apply


def popen(args: list, memory: int = MEMORY, **kw) -> subprocess.Popen:
    """Start `adapt ARGS` in a new process group under a memory limit."""
    return subprocess.Popen([sys.executable, "-m", "adaptbench.cli", *map(str, args)], cwd=kw.pop("cwd", ROOT),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_limits(memory), **kw)


def adapt(args: list, timeout: float = 60, memory: int = MEMORY, **kw) -> subprocess.CompletedProcess:
    """Run `adapt ARGS` to completion (raises TimeoutExpired past `timeout`)."""
    p = popen(args, memory, **kw)
    try:
        out, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, 9)
        p.communicate()
        raise
    return subprocess.CompletedProcess(p.args, p.returncode, out, err)


def keys(path: Path) -> list:
    """(agent, persona, task, seed) of every complete record line, in file order."""
    import json

    out = []
    for line in path.read_bytes().split(b"\n")[:-1]:
        r = json.loads(line)
        out.append((r["agent"], r["persona"], r["task"], r["seed"]))
    return out
