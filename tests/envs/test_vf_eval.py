"""A real `vf-eval adapt_breakfast` (verifiers 0.4) against a local OpenAI-compatible server on the tiny
model: `transformers serve` behind `envs.sse_relay` (which ends its streams with `data: [DONE]`), the
command docs/environments.md gives, with no harness or runtime flag. The episode runs to its step limit
and the trace holds the reward and every metric the entry point records. Slow (about 2 minutes on two
CPU cores): run it with `pytest -m slow tests/envs/test_vf_eval.py`."""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from .serverproc import ROOT, free_port

pytest.importorskip("verifiers.v1", reason="the verifiers extra is not installed: pip install -e '.[verifiers]'")
VF_EVAL = Path(sys.executable).with_name("vf-eval")
TRANSFORMERS = Path(sys.executable).with_name("transformers")
MISSING = [m for m in ("fastapi", "uvicorn", "httpx", "torch") if importlib.util.find_spec(m) is None]

pytestmark = [pytest.mark.slow, pytest.mark.skipif(
    bool(MISSING) or not VF_EVAL.exists() or not TRANSFORMERS.exists() or shutil.which("uv") is None,
    reason=f"needs vf-eval, uv and transformers serve (missing: {MISSING or 'a command'}): "
           "pip install -e '.[verifiers,serve,models]'")]
METRICS = {"preferences_satisfied", "preferences_violated", "questions", "steps", "invalid_actions", "completed"}


def _start(args: list, log: Path, url: str, seconds: float = 180) -> subprocess.Popen:
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "TRANSFORMERS_VERBOSITY": "error", "PYTHONPATH": str(ROOT / "src")}
    with open(log, "wb") as out:
        proc = subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT, env=env, cwd=ROOT)
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"{args[:3]} exited with {proc.returncode}: {log.read_text()[-2000:]}")
        try:
            with urllib.request.urlopen(url, timeout=2) as r:
                if r.status == 200:
                    return proc
        except OSError:
            time.sleep(0.5)
    proc.kill()
    raise TimeoutError(f"{args[:3]} did not answer {url} within {seconds:.0f} s")


def test_vf_eval_runs_an_episode_on_the_tiny_model(tiny, tmp_path):
    serve_port, relay_port = free_port(), free_port()
    procs = []
    try:
        procs.append(_start([str(TRANSFORMERS), "serve", str(tiny), "--device", "cpu", "--host", "127.0.0.1",
                             "--port", str(serve_port)], tmp_path / "serve.log",
                            f"http://127.0.0.1:{serve_port}/v1/models"))
        procs.append(_start([sys.executable, "-m", "adaptbench.envs.sse_relay", "--upstream",
                             f"http://127.0.0.1:{serve_port}", "--port", str(relay_port)], tmp_path / "relay.log",
                            f"http://127.0.0.1:{relay_port}/v1/models"))
        cmd = [str(VF_EVAL), "adapt_breakfast", "-m", str(tiny), "--client.base-url",
               f"http://127.0.0.1:{relay_port}/v1", "--client.api-key-var", "OPENAI_API_KEY", "--no-push",
               "-o", str(tmp_path / "out"), "--env.taskset.personas", "juan", "--env.taskset.tasks", "eggs",
               "--env.taskset.max-steps", "3", "--env.assistant.sampling.max-tokens", "16"]
        env = {**os.environ, "OPENAI_API_KEY": "none", "PYTHONPATH": str(ROOT / "src")}
        run = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env, cwd=tmp_path)
    finally:
        for p in procs:
            p.terminate()
            p.wait(timeout=30)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    traces = list((tmp_path / "out").rglob("traces.jsonl"))
    assert len(traces) == 1
    record = json.loads(traces[0].read_text().splitlines()[0])
    assert record["ok"] and not record["errors"], record["errors"]
    trace = record["traces"][0]
    assert trace["rewards"]["satisfaction_rate"]["weight"] == 1.0
    assert 0.0 <= trace["rewards"]["satisfaction_rate"]["score"] <= 1.0
    m = trace["metrics"]
    assert set(m) == METRICS and (m["steps"] == 3 or m["completed"] == 1)  # the step limit, or Declare Done
    assert trace["info"]["verdicts"]["preferences"]
    assert "satisfaction_rate" in run.stdout and "preferences_violated" in run.stdout
