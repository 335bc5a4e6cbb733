"""The `openai` backend: any OpenAI-compatible completions server (vLLM, SGLang) serving the model.

    backend = OpenAIBackend("http://localhost:8000/v1", model="my-model", tokenizer="path/to/model")

Prompts are rendered and tokenized locally with the model's tokenizer (`tokenizer`: a local directory)
and sent as token ids to `/v1/completions`, so a served model sees exactly what the `transformers`
backend would. The grammar goes the way vLLM's structured outputs take it
(`"structured_outputs": {"grammar": ...}`); what comes back is checked with the request's validator
(the simulator's parser) and, if the server did not enforce the grammar, asked once more (sampled at
temperature 0.7). `score` reads prompt log-probabilities (`echo` + `logprobs`, or vLLM's
`prompt_logprobs`). Requests of one batch are sent concurrently. Standard library only (urllib).

`transformers serve` (transformers 5.x) takes only text prompts and refuses the grammar field (HTTP
422): `OpenAIBackend(..., text_prompts=True, grammar_field=False)` sends the rendered text and leaves
the grammar to the validator and the retry; it offers no prompt log-probabilities, so `score` raises
`ServerError` there (docs/llm.md).
"""

from __future__ import annotations

import json
import time
import urllib.error
import urllib.request
from concurrent.futures import ThreadPoolExecutor

from ..errors import AdaptError
from .backend import Backend, Completion, Scored, cut_at_stop


class ServerError(AdaptError, RuntimeError):
    """The server could not be reached or answered with an error."""


class OpenAIBackend(Backend):
    """A model behind an OpenAI-compatible HTTP server."""

    name = "openai"

    def __init__(self, url: str, model: str, tokenizer: str, api_key: str | None = None, timeout: float = 120.0,
                 concurrency: int = 16, temperature: float = 0.0, text_prompts: bool = False,
                 grammar_field: bool = True):
        from transformers import AutoTokenizer

        self.url, self.model, self.api_key = url.rstrip("/"), model, api_key
        self.text_prompts, self.grammar_field = text_prompts, grammar_field
        self.timeout, self.concurrency, self.temperature = timeout, concurrency, temperature
        self.tokenizer = AutoTokenizer.from_pretrained(tokenizer)
        self.retries = 0  # completions that failed validation and were asked again

    def config(self) -> dict:
        """The server's model name and sampling temperature."""
        return {"backend": self.name, "model": self.model, "temperature": self.temperature}

    def _post(self, path: str, body: dict) -> dict:
        req = urllib.request.Request(self.url + path, json.dumps(body).encode(), method="POST",
                                     headers={"Content-Type": "application/json",
                                              **({"Authorization": f"Bearer {self.api_key}"} if self.api_key else {})})
        try:
            with urllib.request.urlopen(req, timeout=self.timeout) as resp:
                return json.loads(resp.read())
        except urllib.error.HTTPError as exc:
            raise ServerError(f"{self.url}{path}: HTTP {exc.code}: {exc.read()[:300].decode(errors='replace')}") from None
        except (urllib.error.URLError, TimeoutError, ConnectionError) as exc:
            raise ServerError(f"{self.url}{path}: {exc}") from None

    def encode(self, text: str) -> list:
        """Token ids of rendered text (the chat template already holds the special tokens)."""
        return self.tokenizer(text, add_special_tokens=False)["input_ids"]

    def _complete(self, ids: list, req, temperature: float) -> tuple:
        prompt = req.prompt if self.text_prompts else ids
        body = {"model": self.model, "prompt": prompt, "max_tokens": req.max_tokens, "temperature": temperature}
        if req.stop:
            body["stop"] = list(req.stop)
        if req.grammar is not None and self.grammar_field:
            body["structured_outputs"] = {"grammar": req.grammar}
        out = self._post("/completions", body)
        choice = out["choices"][0]
        usage = out.get("usage") or {}
        return cut_at_stop(choice.get("text", ""), req.stop), usage.get("completion_tokens")

    def _one(self, req) -> Completion:
        t0 = time.perf_counter()
        ids = self.encode(req.prompt)
        text, n = self._complete(ids, req, self.temperature)
        tries = 1
        ok = None if req.validate is None else req.validate(text)
        if ok is False:
            self.retries += 1
            text, n = self._complete(ids, req, max(self.temperature, 0.7))
            tries, ok = 2, req.validate(text)
        n = n if n is not None else len(self.encode(text))
        accepted = ok if req.grammar is not None else None
        return Completion(text, len(ids), n, accepted,
                          {"seconds": round(time.perf_counter() - t0, 4), "tries": tries})

    def generate(self, requests) -> list:
        """Completions for the requests, sent concurrently."""
        with ThreadPoolExecutor(max_workers=max(1, min(self.concurrency, len(requests)))) as pool:
            return list(pool.map(self._one, requests))

    def _score_one(self, p: list, cont: str) -> Scored:
        c = self.encode(cont)
        body = {"model": self.model, "prompt": self.tokenizer.decode(p + c) if self.text_prompts else p + c, "max_tokens": 1, "temperature": 0.0, "echo": True,
                "logprobs": 0, "prompt_logprobs": 0}
        choice = self._post("/completions", body)["choices"][0]
        return Scored(cont, _prompt_logprobs(choice, p + c)[len(p):])

    def score(self, prompt: str, continuations) -> list:
        """Per-token log-probabilities of each continuation from the server's prompt log-probs."""
        p = self.encode(prompt)
        with ThreadPoolExecutor(max_workers=max(1, min(self.concurrency, len(continuations)))) as pool:
            return list(pool.map(lambda c: self._score_one(p, c), continuations))


def _prompt_logprobs(choice: dict, ids: list) -> tuple:
    """The log-probability of each prompt token (the first has none: 0.0) from a completions choice:
    vLLM's `prompt_logprobs` (a list of {token id: {logprob}} dicts) or the legacy `echo` form
    (`logprobs.token_logprobs` over prompt then completion)."""
    pl = choice.get("prompt_logprobs")
    if pl is not None:
        out = []
        for tok, entry in zip(ids, pl, strict=False):
            if not entry:
                out.append(0.0)
                continue
            hit = entry.get(str(tok)) or entry.get(tok)
            out.append(float(hit["logprob"] if isinstance(hit, dict) else hit))
        return tuple(out)
    lp = (choice.get("logprobs") or {}).get("token_logprobs")
    if lp is None:
        raise ServerError("the server returned no prompt log-probabilities (needs echo+logprobs or prompt_logprobs)")
    return tuple(0.0 if x is None else float(x) for x in lp[:len(ids)])
