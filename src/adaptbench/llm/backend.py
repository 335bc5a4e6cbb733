"""The backend interface: batched generation under per-row grammars, and scoring of continuations.

    backend = make_backend("transformers", model="models/tiny", device="cpu")
    outs = backend.generate([Request(text, grammar, stop=(), max_tokens=48), ...])
    scores = backend.score(text, ["Look for eggs", "Declare Done"])
    logprobs = backend.score_ids([(prompt_ids, [ids_a, ids_b]), ...])   # [[(lp, lp, ...), ...], ...]

`Request.prompt` is rendered text (`chat.render`): both backends hold the model's tokenizer, so prompts
are rendered, counted and truncated the same way for a local model and a served one. Scoring has one
primitive, `score_ids`: the log-probability of every given completion id after given prompt ids (the
local model's forward pass; a served engine's prompt log-probabilities). `score` is built on it here,
the same for both: the prompt encoded, each text continuation's ids ending with the chat template's end
token (`continuation_ids`).
"""

from __future__ import annotations

import hashlib
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

from ..errors import AdaptError

BACKENDS = ("transformers", "openai")


class ModelError(AdaptError, RuntimeError):
    """A model or server that cannot be used as given (no CUDA, no tokenizer or chat template, a context
    too short, no server listening); the message says what to do. The command line prints it as one line
    and exits 2."""

    exit_code = 2


def check_tokenizer(tokenizer, where: str) -> None:
    """ModelError unless the tokenizer has a chat template (every prompt is rendered with it)."""
    if not getattr(tokenizer, "chat_template", None):
        raise ModelError(f"{where} has no chat template (tokenizer_config.json `chat_template` or "
                         "chat_template.jinja): prompts are rendered with it; use a chat/instruct model "
                         "or add a template")


def load_tokenizer(path: str, **kw):
    """The tokenizer of a local model directory, with its chat template; ModelError when there is none."""
    from pathlib import Path

    from transformers import AutoTokenizer

    if not Path(path).is_dir():
        raise ModelError(f"{path}: not a directory (a model saved with save_pretrained; "
                         "`adapt model init --out DIR` builds the tiny one)")
    try:
        tokenizer = AutoTokenizer.from_pretrained(path, **kw)
    except (OSError, ValueError, TypeError) as exc:
        raise ModelError(f"{path}: no usable tokenizer ({str(exc).splitlines()[0][:200]}); the directory needs "
                         "tokenizer.json or the files of a slow tokenizer, as save_pretrained writes them") from None
    check_tokenizer(tokenizer, path)
    return tokenizer


def check_device(device: str) -> None:
    """ModelError when torch cannot use `device` (cuda on a CPU-only build, a GPU index that is not there)."""
    import torch

    kind, _, index = device.partition(":")
    if kind == "cuda":
        if not torch.cuda.is_available():
            build = "a CPU-only build" if torch.version.cuda is None else "built for CUDA, but no GPU is visible"
            raise ModelError(f"--device {device}: this torch ({torch.__version__}) is {build}; use --device cpu, "
                             "or install a CUDA build of torch on a machine with a GPU")
        if index and (not index.isdigit() or int(index) >= torch.cuda.device_count()):
            raise ModelError(f"--device {device}: no such GPU ({torch.cuda.device_count()} visible)")
    elif kind not in ("cpu", "mps", "xpu", "meta"):
        raise ModelError(f"--device {device}: unknown device (cpu, cuda, cuda:1 ...)")


def context_limit(tokenizer, config=None) -> int | None:
    """The model's context in tokens: the smaller of the model configuration's `max_position_embeddings`
    and the tokenizer's `model_max_length` (ignored when it is a placeholder); None when neither says."""
    limits = [getattr(config, "max_position_embeddings", None), getattr(tokenizer, "model_max_length", None)]
    limits = [x for x in limits if isinstance(x, int) and 0 < x < 1_000_000]
    return min(limits) if limits else None


@dataclass(frozen=True)
class Request:
    """One generation: rendered prompt text, a Lark grammar (None: unconstrained), stop strings
    (the completion is cut before the first), a token limit, and a validator for what comes back
    (`text -> bool`; used where the grammar may not be enforced, e.g. a server without grammars), and
    a session key: requests of one session (an episode's steps) extend each other's prompts, so a
    backend may keep the session's key/value cache and read only the new tokens. `key` names the
    request's own random stream when the backend samples (`llm.sampling`: an episode's step, e.g.
    `planner/juan/eggs/0/3/action`; None: the backend's run generator), and `temperature` overrides the
    backend's for this request (the LLM user answers greedily: 0.0)."""

    prompt: str
    grammar: str | None = None
    stop: tuple = ()
    max_tokens: int = 64
    validate: object = field(default=None, compare=False)
    session: str | None = None
    key: str | None = None
    temperature: float | None = None


@dataclass(frozen=True)
class Completion:
    """What came back: the text, tokens in the prompt and generated, whether the grammar accepted the
    text (None when unconstrained), timings and other statistics, and `token_ids`: the ids the model
    generated, in order, the end token included when one was generated (None where the backend cannot
    know them: a server that returns no ids). The text may be shorter than the ids (cut at a stop
    string, a healed prompt's spaces taken off: `boundary`); `stats["canonical"]` says whether the ids
    are the tokenizer's own encoding of their text (`canonical`)."""

    text: str
    prompt_tokens: int
    tokens: int
    accepted: bool | None = None
    stats: dict = field(default_factory=dict)
    token_ids: tuple | None = None


@dataclass(frozen=True)
class Scored:
    """A continuation's per-token log-probabilities under the model, the ids they are of (a text
    continuation's ids end with the end token: it is scored as a complete answer), and their mean
    probability (the arithmetic mean of the tokens' softmax probabilities, Reflection-DPO's P(a | x))."""

    text: str
    logprobs: tuple
    token_ids: tuple = ()

    @property
    def mean_prob(self) -> float:
        """The mean of the tokens' probabilities (0.0 for an empty continuation)."""
        return mean_prob(self.logprobs)


def mean_prob(logprobs) -> float:
    """The arithmetic mean of the probabilities of per-token log-probabilities (0.0 for none):
    Reflection-DPO's P(a | x)."""
    import math

    return sum(math.exp(x) for x in logprobs) / len(logprobs) if logprobs else 0.0


class Backend(ABC):
    """A language model that generates under grammars and scores continuations."""

    name = "backend"
    tokenizer = None
    context = None  # the model's context in tokens, when known

    @abstractmethod
    def generate(self, requests) -> list:
        """One `Completion` per `Request`, in order (batched where the backend can)."""

    @abstractmethod
    def encode(self, text: str) -> list:
        """Token ids of rendered text (no special tokens added: the chat template holds them)."""

    @abstractmethod
    def score_ids(self, groups, dtype: str | None = None) -> list:
        """The scoring primitive: for each `(prompt ids, [completion ids, ...])` group, per completion
        the log-probability of each of its ids after the prompt and the completion's ids before it (a
        tuple of floats, one per id), in order: a list of lists. A group's prompt may be read once for
        all its completions; groups are independent. `dtype` ("float32"): the precision of the forward
        pass, where the backend can choose it (`score_dtype` says which it is)."""

    def score(self, prompt: str, continuations, dtype: str | None = None) -> list:
        """One `Scored` per continuation of the rendered `prompt`. A continuation is text, scored as a
        complete answer (its canonical tokens and the end token the chat template closes an assistant
        turn with: `continuation_ids`), or a sequence of token ids, scored as they are (a completion's
        `token_ids`). One `score_ids` group."""
        conts = [continuation_ids(self.tokenizer, c) for c in continuations]
        if not conts:
            return []
        (lps,) = self.score_ids([(self.encode(prompt), conts)], dtype=dtype)
        return [Scored(c if isinstance(c, str) else self.tokenizer.decode(ids, skip_special_tokens=True), lp,
                       tuple(ids))
                for c, ids, lp in zip(continuations, conts, lps, strict=True)]

    def score_dtype(self, dtype: str | None = None) -> str:
        """The precision `score(..., dtype)` runs the model in ("server": whatever the server uses)."""
        return "server"

    def config(self) -> dict:
        """What identifies the model (recorded with each episode)."""
        return {"backend": self.name}

    def release(self, session: str) -> None:  # noqa: B027 - optional hook, nothing to release by default
        """Forget whatever is kept for a session (its episode ended)."""


SEED_RANGE = 2**31  # request seeds (`llm.sampling`) fit a 32-bit signed int: what every server's `seed` takes


def request_seed(sample_seed: int, key: str) -> int:
    """The seed of a keyed request: a stable hash of the run's sample seed and the key (the same in
    every process and on every machine), in [0, 2**31)."""
    digest = hashlib.blake2b(f"{sample_seed}\x00{key}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "big") % SEED_RANGE


def sampling_config(temperature: float, seed: int) -> dict:
    """What a backend records of its sampling: the temperature, and the sample seed when it samples (a
    greedy run is the same under every seed, so its episodes match whatever `--sample-seed` said)."""
    return {"temperature": temperature, **({"sample_seed": seed} if temperature > 0 else {})}


def make_backend(kind: str, **kw) -> Backend:
    """A backend by name: `transformers` (model=PATH, device, dtype) or `openai` (url, model, tokenizer)."""
    if kind == "transformers":
        from .hf import TransformersBackend

        return TransformersBackend(**kw)
    if kind == "openai":
        from .openai_backend import OpenAIBackend

        return OpenAIBackend(**kw)
    raise ValueError(f"unknown backend '{kind}' (choose from: {', '.join(BACKENDS)})")


def cut_at_stop(text: str, stop) -> str:
    """The text before the first stop string."""
    cut = len(text)
    for s in stop:
        i = text.find(s)
        if s and 0 <= i < cut:
            cut = i
    return text[:cut]


def continuation_ids(tokenizer, continuation) -> list:
    """The token ids a continuation is scored on: a text's canonical tokens followed by the end token
    the chat template closes an assistant turn with (`chat.end_token`), so that an answer is charged
    for stopping where it stops ("Look for eggs" is not a free prefix of "Look for eggs in the
    fridge"); a sequence of ids as it is."""
    if isinstance(continuation, str):
        from .chat import end_token

        ids = tokenizer(continuation, add_special_tokens=False)["input_ids"]
        end = end_token(tokenizer)
        return [*ids, end] if end is not None else list(ids)
    return [int(t) for t in continuation]


def canonical(tokenizer, ids) -> bool:
    """Whether generated ids (a final end token set aside) are the tokenizer's own encoding of the
    text they decode to. A grammar-constrained decoder may take other splits of the same bytes
    (`quart`+`er` for `quarter`; a forced `_0 ` after `oven` where the tokenizer writes `oven_0 `):
    on-policy training must then use the ids, not a re-tokenization of the text."""
    from .chat import end_token

    body = list(ids)
    if body and body[-1] in {end_token(tokenizer), tokenizer.eos_token_id}:
        body = body[:-1]
    text = tokenizer.decode(body, skip_special_tokens=False, clean_up_tokenization_spaces=False)
    return tokenizer(text, add_special_tokens=False)["input_ids"] == body
