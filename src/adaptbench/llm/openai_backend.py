"""The `openai` backend: any OpenAI-compatible completions server (vLLM, SGLang) serving the model.

    backend = OpenAIBackend("http://localhost:8000/v1", model="my-model", tokenizer="path/to/model")

Prompts are rendered and tokenized locally with the model's tokenizer (`tokenizer`: a local directory)
and sent as token ids to `/v1/completions`, so a served model sees exactly what the `transformers`
backend would. The grammar goes the way vLLM's structured outputs take it
(`"structured_outputs": {"grammar": ...}`); what comes back is checked with the request's validator
(the simulator's parser) and, if the server did not enforce the grammar, asked once more (sampled at
temperature 0.7). A completion carries its generated ids where the server returns them (vLLM's
`return_token_ids`; None otherwise: `transformers serve`). `score_ids` (the scoring primitive `score`
is built on, `backend`) reads the server's prompt log-probabilities of prompt ids followed by completion
ids (vLLM's `prompt_logprobs`, or `echo` + `logprobs`), so a served engine scores exactly the ids the
local backend would. Requests of one batch are sent concurrently. Standard library only (urllib).

`transformers serve` (transformers 5.x) takes only text prompts and refuses the grammar field (HTTP
422): `OpenAIBackend(..., text_prompts=True, grammar_field=False)` sends the rendered text and leaves
the grammar to the validator and the retry; it offers no prompt log-probabilities, so `score` raises
`ServerError` there (docs/llm.md).
"""

from __future__ import annotations

import json
import random
import time
import urllib.error
import urllib.request
from concurrent.futures import ThreadPoolExecutor

from .backend import (
    SEED_RANGE,
    Backend,
    Completion,
    ModelError,
    canonical,
    context_limit,
    cut_at_stop,
    load_tokenizer,
    request_seed,
    sampling_config,
)


class ServerError(ModelError):
    """The server could not be reached or answered with an error; the message says what to do
    (`status`: the HTTP status when it answered one)."""

    def __init__(self, message: str, status: int | None = None):
        super().__init__(message)
        self.status = status


class OpenAIBackend(Backend):
    """A model behind an OpenAI-compatible HTTP server."""

    name = "openai"

    def __init__(self, url: str, model: str, tokenizer: str, api_key: str | None = None, timeout: float = 120.0,
                 concurrency: int = 16, temperature: float = 0.0, text_prompts: bool = False,
                 grammar_field: bool = True, seed: int = 0):
        self.url, self.model, self.api_key = url.rstrip("/"), model, api_key
        self.seed, self._rng = seed, random.Random(seed)  # the run's seeds for requests without a key
        self.text_prompts, self.grammar_field = text_prompts, grammar_field
        self.timeout, self.concurrency, self.temperature = timeout, concurrency, temperature
        self.tokenizer = load_tokenizer(tokenizer)
        self.context = context_limit(self.tokenizer)
        self.retries = 0  # completions that failed validation and were asked again

    def config(self) -> dict:
        """The server's model name, sampling temperature and, when sampling, the sample seed."""
        return {"backend": self.name, "model": self.model, **sampling_config(self.temperature, self.seed)}

    def _seed(self, req) -> int:
        """The `seed` sent with a request (`llm.sampling`): derived from the sample seed and the request's key
        like the transformers backend's generators, else the next of the run's seeds."""
        return request_seed(self.seed, req.key) if req.key is not None else self._rng.randrange(SEED_RANGE)

    def _post(self, path: str, body: dict | None) -> dict:
        """POST `body` (GET when None) and return the JSON answer; ServerError saying what to do."""
        req = urllib.request.Request(self.url + path, None if body is None else json.dumps(body).encode(),
                                     method="GET" if body is None else "POST",
                                     headers={"Content-Type": "application/json",
                                              **({"Authorization": f"Bearer {self.api_key}"} if self.api_key else {})})
        try:
            with urllib.request.urlopen(req, timeout=self.timeout) as resp:
                return json.loads(resp.read())
        except urllib.error.HTTPError as exc:
            raise ServerError(http_advice(self.url + path, exc.code, exc.read()[:400].decode(errors="replace"),
                                          body or {}), exc.code) from None
        except (urllib.error.URLError, TimeoutError, ConnectionError) as exc:
            reason = getattr(exc, "reason", exc)
            raise ServerError(f"no answer from {self.url} ({reason}): start the server first (docs/llm.md), "
                              "or point --url at it") from None
        except json.JSONDecodeError:
            raise ServerError(f"{self.url}{path} did not answer JSON: is --url an OpenAI-compatible /v1?") from None

    def probe(self) -> None:
        """Check before any episode that the server answers and serves `model` (GET /models); learn
        its context (vLLM's `max_model_len`). ServerError saying what to do; a server without /models
        passes (transformers 5.23 answers HTTP 500 there without a hub cache)."""
        try:
            listing = self._post("/models", None)
        except ServerError as exc:
            if exc.status is not None:  # it answers, without a model list (or a broken one)
                return
            raise
        models = {m.get("id"): m for m in listing.get("data") or () if isinstance(m, dict)}
        if models and self.model not in models:
            raise ServerError(f"the server at {self.url} serves {', '.join(map(repr, models))}, not "
                              f"'{self.model}': pass --model exactly as the server names it (a path as given "
                              "to the server) and --tokenizer DIR for the local tokenizer")
        served = (models.get(self.model) or {}).get("max_model_len")
        if isinstance(served, int) and served > 0:
            self.context = min(served, self.context or served)

    def encode(self, text: str) -> list:
        """Token ids of rendered text (the chat template already holds the special tokens)."""
        return self.tokenizer(text, add_special_tokens=False)["input_ids"]

    def _complete(self, ids: list, req, temperature: float, seed: int) -> tuple:
        prompt = req.prompt if self.text_prompts else ids
        body = {"model": self.model, "prompt": prompt, "max_tokens": req.max_tokens, "temperature": temperature}
        if temperature > 0:
            body["seed"] = seed
        if req.stop:
            body["stop"] = list(req.stop)
        if req.grammar is not None and self.grammar_field:
            body["structured_outputs"] = {"grammar": req.grammar}
        if not self.text_prompts:
            body["return_token_ids"] = True  # vLLM: the generated ids (EOS included) in `choices[0].token_ids`
        out = self._post("/completions", body)
        choice = out["choices"][0]
        usage = out.get("usage") or {}
        ids = choice.get("token_ids")
        ids = tuple(int(t) for t in ids) if isinstance(ids, list) else None
        return cut_at_stop(choice.get("text", ""), req.stop), usage.get("completion_tokens"), ids

    def _one(self, req, seed: int) -> Completion:
        t0 = time.perf_counter()
        ids = self.encode(req.prompt)
        temperature = self.temperature if req.temperature is None else req.temperature
        text, n, out_ids = self._complete(ids, req, temperature, seed)
        tries = 1
        ok = None if req.validate is None else req.validate(text)
        if ok is False:
            self.retries += 1
            text, n, out_ids = self._complete(ids, req, max(temperature, 0.7), (seed + 1) % SEED_RANGE)
            tries, ok = 2, req.validate(text)
        n = n if n is not None else len(out_ids) if out_ids is not None else len(self.encode(text))
        accepted = ok if req.grammar is not None else None
        stats = {"seconds": round(time.perf_counter() - t0, 4), "tries": tries}
        if out_ids is not None:
            stats["canonical"] = canonical(self.tokenizer, out_ids)
        return Completion(text, len(ids), n, accepted, stats, out_ids)

    def generate(self, requests) -> list:
        """Completions for the requests, sent concurrently (each with its `seed`, chosen here in order)."""
        seeds = [self._seed(r) for r in requests]
        with ThreadPoolExecutor(max_workers=max(1, min(self.concurrency, len(requests)))) as pool:
            return list(pool.map(self._one, requests, seeds))

    def _score_one(self, prompt: list, completion: list) -> tuple:
        ids = list(prompt) + list(completion)
        body = {"model": self.model, "prompt": self.tokenizer.decode(ids) if self.text_prompts else ids,
                "max_tokens": 1, "temperature": 0.0, "echo": True, "logprobs": 0, "prompt_logprobs": 0}
        choice = self._post("/completions", body)["choices"][0]
        return _prompt_logprobs(choice, ids, self.url)[len(prompt):]

    def score_ids(self, groups, dtype: str | None = None) -> list:
        """Per-token log-probabilities of each group's completions (`Backend.score_ids`) from the
        server's prompt log-probabilities: one request per completion (prompt ids then completion ids,
        echoed, one token generated), all of them sent concurrently; in the server's precision (`dtype`
        cannot change it). ServerError when the server returns none."""
        jobs = [(g, list(prompt), list(c)) for g, (prompt, conts) in enumerate(groups) for c in conts]
        out: list = [[] for _ in groups]
        if not jobs:
            return out
        with ThreadPoolExecutor(max_workers=max(1, min(self.concurrency, len(jobs)))) as pool:
            for (g, _, _), lps in zip(jobs, pool.map(lambda j: self._score_one(j[1], j[2]), jobs), strict=True):
                out[g].append(lps)
        return out

    def check_scoring(self) -> None:
        """ServerError unless the server returns prompt log-probabilities for token-id prompts (vLLM's
        `prompt_logprobs`, or `echo` with `logprobs`): one short prompt scored before any episode."""
        ids = self.encode(self.tokenizer.apply_chat_template([{"role": "user", "content": "Hello"}],
                                                             tokenize=False, add_generation_prompt=True))
        self.score_ids([(ids[:-1] or ids, [ids[-1:]])])


NO_LOGPROBS = ("returned no prompt log-probabilities: scoring needs vLLM's `prompt_logprobs` (or `echo` with "
               "`logprobs`) on token-id prompts; serve the model with vLLM (docs/llm.md)")


def _prompt_logprobs(choice: dict, ids: list, url: str = "the server") -> tuple:
    """The log-probability of each prompt token (the first has none: 0.0) from a completions choice:
    vLLM's `prompt_logprobs` (a list of {token id: {logprob}} dicts) or the legacy `echo` form
    (`logprobs.token_logprobs` over prompt then completion). ServerError when neither is there, or
    they do not cover every prompt token."""
    pl = choice.get("prompt_logprobs")
    if pl is not None:
        out = []
        for tok, entry in zip(ids, pl, strict=False):
            if not entry:
                out.append(0.0)
                continue
            hit = entry.get(str(tok)) or entry.get(tok)
            if hit is None:
                raise ServerError(f"{url} returned prompt log-probabilities without the prompt's own token {tok}")
            out.append(float(hit["logprob"] if isinstance(hit, dict) else hit))
    else:
        lp = (choice.get("logprobs") or {}).get("token_logprobs")
        if lp is None:
            raise ServerError(f"{url} {NO_LOGPROBS}")
        out = [0.0 if x is None else float(x) for x in lp[:len(ids)]]
    if len(out) < len(ids):
        raise ServerError(f"{url} returned {len(out)} prompt log-probabilities for {len(ids)} prompt tokens: {NO_LOGPROBS}")
    return tuple(out)


def http_advice(where: str, code: int, text: str, body: dict) -> str:
    """One message for a server's HTTP error, with what to do for the ones users meet."""
    if code == 400 and "pinned to" in text:
        return (f"{where}: HTTP 400: {text.strip()[:200]}: pass --model exactly as the server was started with "
                "(transformers serve compares the text; a relative path differs from an absolute one) and "
                "--tokenizer DIR for the local tokenizer")
    if code == 422 or (code == 400 and "structured_outputs" in text):
        return (f"{where}: HTTP {code}: the server refused the request ({text.strip()[:160]}); a server "
                "without vLLM's `structured_outputs` grammar field or token-id prompts (such as transformers "
                "serve) needs --server transformers-serve")
    return f"{where}: HTTP {code}: {text.strip()[:300]}"
