"""The backend interface: batched generation under per-row grammars, and scoring of continuations.

    backend = make_backend("transformers", model="models/tiny", device="cpu")
    outs = backend.generate([Request(text, grammar, stop=(), max_tokens=48), ...])
    scores = backend.score(text, ["Look for eggs", "Declare Done"])

`Request.prompt` is rendered text (`chat.render`): both backends hold the model's tokenizer, so prompts
are rendered, counted and truncated the same way for a local model and a served one.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

BACKENDS = ("transformers", "openai")


@dataclass(frozen=True)
class Request:
    """One generation: rendered prompt text, a Lark grammar (None: unconstrained), stop strings
    (the completion is cut before the first), a token limit, and a validator for what comes back
    (`text -> bool`; used where the grammar may not be enforced, e.g. a server without grammars), and
    a session key: requests of one session (an episode's steps) extend each other's prompts, so a
    backend may keep the session's key/value cache and read only the new tokens."""

    prompt: str
    grammar: str | None = None
    stop: tuple = ()
    max_tokens: int = 64
    validate: object = field(default=None, compare=False)
    session: str | None = None


@dataclass(frozen=True)
class Completion:
    """What came back: the text, tokens in the prompt and generated, whether the grammar accepted the
    text (None when unconstrained), and timings and other statistics."""

    text: str
    prompt_tokens: int
    tokens: int
    accepted: bool | None = None
    stats: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Scored:
    """A continuation's per-token log-probabilities under the model and their mean probability
    (the arithmetic mean of the tokens' softmax probabilities, Reflection-DPO's P(a | x))."""

    text: str
    logprobs: tuple

    @property
    def mean_prob(self) -> float:
        """The mean of the tokens' probabilities (0.0 for an empty continuation)."""
        import math

        return sum(math.exp(x) for x in self.logprobs) / len(self.logprobs) if self.logprobs else 0.0


class Backend(ABC):
    """A language model that generates under grammars and scores continuations."""

    name = "backend"
    tokenizer = None

    @abstractmethod
    def generate(self, requests) -> list:
        """One `Completion` per `Request`, in order (batched where the backend can)."""

    @abstractmethod
    def score(self, prompt: str, continuations) -> list:
        """One `Scored` per continuation of the rendered `prompt`."""

    def config(self) -> dict:
        """What identifies the model (recorded with each episode)."""
        return {"backend": self.name}

    def release(self, session: str) -> None:  # noqa: B027 - optional hook, nothing to release by default
        """Forget whatever is kept for a session (its episode ended)."""


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
