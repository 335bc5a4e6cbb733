"""Model and server mistakes a user makes, each run as a whole `adapt rollout` process: one `adapt:` line
that says what to do, exit code 2, no traceback, and no results file left behind."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from ..conftest import ROOT, SPEC
from .conftest import SKIP_MODELS

pytestmark = SKIP_MODELS


def adapt(*args, out):
    """Run `adapt rollout` for one short planner episode; (exit code, stderr)."""
    cmd = [sys.executable, "-m", "adaptbench.cli", "rollout", "--agent", "planner", "--personas", "juan",
           "--tasks", "eggs", "--seeds", "0", "--max-steps", "2", "--quiet", "--spec", str(SPEC),
           "--out", str(out), *args]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=300)
    return proc.returncode, proc.stderr


def assert_one_message(rc: int, err: str, *words: str) -> str:
    lines = [line for line in err.splitlines() if line.startswith("adapt: ")]
    assert rc == 2 and "Traceback" not in err and len(lines) == 1, err
    assert all(w in lines[0] for w in words), lines[0]
    return lines[0]


def canned_server(models, status: int, detail):
    """A server answering GET /v1/models with `models` (None: 404) and every POST with `status` and
    {"detail": detail}, as transformers serve and FastAPI servers do."""

    class Handler(BaseHTTPRequestHandler):
        def log_message(self, *args):
            pass

        def _send(self, code: int, body) -> None:
            data = json.dumps(body).encode()
            self.send_response(code)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            self.wfile.write(data)

        def do_GET(self):  # noqa: N802
            if models is None:
                self._send(404, {"detail": "Not Found"})
            else:
                self._send(200, {"object": "list", "data": [{"id": m, "object": "model"} for m in models]})

        def do_POST(self):  # noqa: N802
            self.rfile.read(int(self.headers.get("Content-Length", 0)))
            self._send(status, {"detail": detail})

    server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}/v1"


@pytest.fixture
def server(request):
    srv, url = canned_server(*request.param)
    yield url
    srv.shutdown()


def test_cuda_on_a_cpu_only_torch(tiny, tmp_path):
    import torch

    if torch.cuda.is_available():
        pytest.skip("this torch has CUDA and a GPU")
    out = tmp_path / "r.jsonl"
    assert_one_message(*adapt("--model", str(tiny), "--device", "cuda", out=out), "--device cuda", "--device cpu")
    assert not out.exists()


def test_no_server_listening_leaves_no_results_file(tiny, tmp_path):
    with __import__("socket").socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # closed again: nothing listens there
    out = tmp_path / "runs" / "r.jsonl"
    rc, err = adapt("--backend", "openai", "--url", f"http://127.0.0.1:{port}/v1", "--model", str(tiny), out=out)
    assert_one_message(rc, err, "no answer from", "start the server")
    assert not out.exists()


@pytest.mark.parametrize("server", [(["/srv/models/tiny"], 400, "Server is pinned to '/srv/models/tiny'; "
                                     "requested 'models/tiny'.")], indirect=True)
def test_model_name_the_server_does_not_serve(tiny, tmp_path, server):
    out = tmp_path / "r.jsonl"
    rc, err = adapt("--backend", "openai", "--url", server, "--model", str(tiny), "--server", "transformers-serve",
                    out=out)
    assert_one_message(rc, err, "'/srv/models/tiny'", "pass --model exactly as the server names it")
    assert not out.exists()


@pytest.mark.parametrize("server", [(None, 400, "Server is pinned to '/srv/models/tiny'; requested 'x'.")],
                         indirect=True)
def test_pinned_server_without_a_model_list(tiny, tmp_path, server):
    out = tmp_path / "r.jsonl"
    rc, err = adapt("--backend", "openai", "--url", server, "--model", str(tiny), "--server", "transformers-serve",
                    out=out)
    assert_one_message(rc, err, "HTTP 400", "pass --model exactly as the server was started with")
    assert not out.exists()


@pytest.mark.parametrize("server", [(None, 422, [{"type": "extra_forbidden", "loc": ["body", "structured_outputs"],
                                                  "msg": "Extra inputs are not permitted"}])], indirect=True)
def test_server_refusing_structured_outputs(tiny, tmp_path, server):
    out = tmp_path / "r.jsonl"
    rc, err = adapt("--backend", "openai", "--url", server, "--model", str(tiny), out=out)
    assert_one_message(rc, err, "HTTP 422", "--server transformers-serve")
    assert not out.exists()


def test_model_directory_without_a_tokenizer(tiny, tmp_path):
    model = tmp_path / "m"
    model.mkdir()
    for name in ("config.json", "model.safetensors"):
        shutil.copy(tiny / name, model / name)
    out = tmp_path / "r.jsonl"
    assert_one_message(*adapt("--model", str(model), out=out), "no usable tokenizer")
    assert not out.exists()


def test_model_without_a_chat_template(tiny, tmp_path):
    model = tmp_path / "m"
    shutil.copytree(tiny, model)
    (model / "chat_template.jinja").unlink(missing_ok=True)
    config = json.loads((model / "tokenizer_config.json").read_text())
    config.pop("chat_template", None)
    (model / "tokenizer_config.json").write_text(json.dumps(config))
    out = tmp_path / "r.jsonl"
    assert_one_message(*adapt("--model", str(model), out=out), "no chat template")
    assert not out.exists()


def test_context_shorter_than_the_prompt(tiny, tmp_path):
    model = tmp_path / "m"
    shutil.copytree(tiny, model)
    config = json.loads((model / "config.json").read_text())
    config["max_position_embeddings"] = 512
    (model / "config.json").write_text(json.dumps(config))
    out = tmp_path / "r.jsonl"
    assert_one_message(*adapt("--model", str(model), out=out), "context (512 tokens)", "longer context")
    assert not out.exists()
    rc, err = adapt("--model", str(tiny), "--budget", "99999", out=out)
    assert_one_message(rc, err, "--budget 99999", "exceeds the model's context")
