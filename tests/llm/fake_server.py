"""A small OpenAI-compatible completions server over the tiny model, for testing the `openai` backend
(standard library http.server in a thread). It takes token-id prompts, vLLM's
`structured_outputs: {"grammar": ...}` (ignored when `enforce` is False, like a server without
grammar support), prompt log-probabilities (`logprobs="echo"`: the legacy `echo` + `logprobs` form;
`"vllm"`: vLLM's `prompt_logprobs` field, a {token id: {logprob, rank, decoded_token}} dict per prompt
token; `"none"`: none, like a server that ignores both and just generates), vLLM's `return_token_ids`,
and `temperature` with `seed` the way vLLM takes them (a request with a seed is sampled from a
generator of its own). `server.bodies` keeps every request body."""

from __future__ import annotations

import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer


def _prompt_logprobs(backend, ids: list) -> list:
    """The log-probability of each prompt token after the ones before it (None for the first)."""
    import torch

    with torch.no_grad():
        logits = backend.model(input_ids=torch.tensor([ids])).logits[0].float()
    logp = torch.log_softmax(logits, -1)
    return [None] + [logp[i - 1, t].item() for i, t in enumerate(ids) if i > 0]


def serve(backend, enforce: bool = True, logprobs: str = "echo"):
    """Start a server in a daemon thread; returns (server, base url). `server.shutdown()` stops it."""

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
                if logprobs == "echo" and body.get("echo"):
                    lps = _prompt_logprobs(backend, ids)
                    out = {"choices": [{"text": "", "logprobs": {"token_logprobs": lps}}]}
                elif logprobs == "vllm" and body.get("prompt_logprobs") is not None:
                    lps = _prompt_logprobs(backend, ids)
                    pl = [None] + [{str(t): {"logprob": x, "rank": 1, "decoded_token": backend.tokenizer.decode([t])}}
                                   for t, x in zip(ids[1:], lps[1:], strict=True)]
                    out = {"choices": [{"text": "", "prompt_logprobs": pl}]}
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
