"""The `openai` backend against a real server: `transformers serve` (transformers 5.x) serving the tiny
model directory on the CPU, started on a free port and stopped at the end. The server takes text
prompts only, refuses the grammar field and offers no prompt log-probabilities, so completions are
validated by the simulator's parser, asked again once when invalid, and `score` is a clear error.
Skipped, saying why, without the serving dependencies (`pip install "transformers[serving]"`)."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from ..procs import free_port, stop
from .conftest import SKIP_MODELS
from .test_openai import _request

SERVING_DEPS = ("fastapi", "uvicorn", "openai")
SERVING_MISSING = [m for m in SERVING_DEPS if importlib.util.find_spec(m) is None]
CLI = Path(sys.executable).with_name("transformers")

pytestmark = [SKIP_MODELS, pytest.mark.skipif(
    bool(SERVING_MISSING) or not CLI.exists(),
    reason=f"transformers serve needs the serving extra (missing {', '.join(SERVING_MISSING) or 'the transformers CLI'}): "
           'pip install "transformers[serving]"')]


def _wait(url: str, proc, seconds: float = 90.0) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"transformers serve exited with code {proc.returncode}")
        try:
            with urllib.request.urlopen(url + "/health", timeout=2):
                return
        except OSError:
            time.sleep(0.5)
    raise TimeoutError(f"transformers serve did not answer on {url} within {seconds:.0f} s")


@pytest.fixture(scope="module")
def served(tiny, tmp_path_factory):
    """(url, model name) of `transformers serve` on the tiny model; the server is stopped afterwards."""
    port = free_port()
    log = tmp_path_factory.mktemp("serve") / "serve.log"
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "TRANSFORMERS_VERBOSITY": "error"}
    with open(log, "wb") as out:
        proc = subprocess.Popen([str(CLI), "serve", str(tiny), "--device", "cpu", "--host", "127.0.0.1",
                                 "--port", str(port)], stdout=out, stderr=subprocess.STDOUT, env=env)
    try:
        _wait(f"http://127.0.0.1:{port}", proc)
        yield f"http://127.0.0.1:{port}/v1", str(tiny)
    except (RuntimeError, TimeoutError) as exc:
        pytest.fail(f"{exc}\n{log.read_text()[-2000:]}")
    finally:
        stop(proc)


def _backend(served, tiny):
    from adaptbench.llm.openai_backend import OpenAIBackend

    url, name = served
    return OpenAIBackend(url, name, str(tiny), text_prompts=True, grammar_field=False, timeout=60)


def test_generate_through_transformers_serve_validates_and_retries(domain, tiny, served):
    from adaptbench.llm.backend import Request
    from adaptbench.runtime.index import runtime_index

    ob = _backend(served, tiny)
    parser = runtime_index(domain).parser
    req = _request(domain, ob.tokenizer, parser)
    outs = ob.generate([req, req, req])
    # the server ignores grammars: the random model's free text never parses, so each is asked again
    # once (sampled) and reported as not accepted
    assert len(outs) == 3 and ob.retries == 3
    assert all(o.accepted is False and o.stats["tries"] == 2 and parser.parse(o.text) is None for o in outs)
    assert all(o.tokens <= req.max_tokens and o.prompt_tokens == len(ob.encode(req.prompt)) for o in outs)
    # an unconstrained request is neither validated nor retried; greedy decoding is deterministic
    free = Request(req.prompt, None, (), 6)
    a, b = ob.generate([free, free])
    assert a.accepted is None and a.text == b.text and a.tokens <= 6 and ob.retries == 3


def test_a_validator_that_accepts_is_not_retried(domain, tiny, served):
    from adaptbench.llm.backend import Request

    ob = _backend(served, tiny)
    req = _request(domain, ob.tokenizer, None)
    out = ob.generate([Request(req.prompt, req.grammar, (), 4, lambda t: True)])[0]
    assert out.accepted is True and out.stats["tries"] == 1 and ob.retries == 0


def test_score_is_a_clear_error_without_prompt_logprobs(domain, tiny, served):
    from adaptbench.llm.openai_backend import ServerError

    ob = _backend(served, tiny)
    with pytest.raises(ServerError, match="prompt_logprobs|log-probabilities"):
        ob.score(_request(domain, ob.tokenizer, None).prompt, ["Look for eggs"])


def test_cli_rollout_through_transformers_serve(tiny, served, tmp_path):
    import json

    from adaptbench.cli import main

    url, name = served
    out = tmp_path / "r.jsonl"
    code = main(["rollout", "--agent", "planner", "--backend", "openai", "--server", "transformers-serve", "--url", url,
                 "--model", name, "--personas", "juan", "--tasks", "eggs", "--seeds", "0", "--max-steps", "2",
                 "--out", str(out)])
    rec = json.loads(out.read_text().splitlines()[0])
    assert code == 0 and len(rec["steps"]) == 2 and all(s["stats"]["tries"] == 2 for s in rec["steps"])
