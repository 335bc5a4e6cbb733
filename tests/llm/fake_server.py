"""A small OpenAI-compatible completions server over the tiny model, for testing the `openai` backend
(standard library http.server in a thread). It takes token-id prompts, vLLM's
`structured_outputs: {"grammar": ...}` (ignored when `enforce` is False, like a server without
grammar support), `echo` + `logprobs` for prompt log-probabilities, vLLM's `return_token_ids`, and `temperature` with `seed` the way
vLLM takes them (a request with a seed is sampled from a generator of its own). `server.bodies` keeps
every request body."""

from __future__ import annotations

import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer


def serve(backend, enforce: bool = True):
    """Start a server in a daemon thread; returns (server, base url). `server.shutdown()` stops it."""
    import torch

    from adaptbench.llm.backend import Request

    lock = threading.Lock()

    class Handler(BaseHTTPRequestHandler):
        def log_message(self, *args):  # quiet
            pass

        def do_POST(self):  # noqa: N802 - http.server's name
            body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
            server.bodies.append(body)
            ids = body["prompt"]
            with lock:
                if body.get("echo"):
                    with torch.no_grad():
                        logits = backend.model(input_ids=torch.tensor([ids])).logits[0].float()
                    logp = torch.log_softmax(logits, -1)
                    lps = [None] + [logp[i - 1, t].item() for i, t in enumerate(ids) if i > 0]
                    out = {"choices": [{"text": "", "logprobs": {"token_logprobs": lps}}]}
                else:
                    grammar = (body.get("structured_outputs") or {}).get("grammar") if enforce else None
                    text = backend.tokenizer.decode(ids)
                    seeded = {"key": f"seed/{body['seed']}", "temperature": body.get("temperature", 1.0)} \
                        if "seed" in body else {}
                    c = backend.generate([Request(text, grammar, tuple(body.get("stop") or ()),
                                                  body.get("max_tokens", 16), **seeded)])[0]
                    out = {"choices": [{"text": c.text}], "usage": {"completion_tokens": c.tokens}}
                    if body.get("return_token_ids"):  # vLLM's field: the generated ids, EOS included
                        out["choices"][0]["token_ids"] = list(c.token_ids)
            data = json.dumps(out).encode()
            self.send_response(200)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            self.wfile.write(data)

    server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    server.bodies = []
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}/v1"
