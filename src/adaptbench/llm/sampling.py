"""Which random numbers a sampled token is drawn with: reproducible runs, and episodes whose samples do not
depend on what they were batched with.

    seed = request_seed(sample_seed, "planner/juan/eggs/0/3/action")   # stable: blake2b, 0 <= seed < 2**31
    sampler = RowSampler([1.0, 0.0], [generator(seed), None])           # one temperature and generator per row
    tokens = sampler.pick(logits, rows)                                   # each row drawn with its own generator

- A request with a `key` (`Request.key`: the policies pass `<agent>/<persona>/<task>/<scene seed>/<step>/<call>`)
  is sampled with a generator of its own, seeded from (the run's sample seed, the key) by a stable hash
  (never Python's `hash()`, which differs per process). An episode's samples are then the same alone, in a
  batch of any size, in any worker process, in any order, and again in a new process.
- A request without a key draws from the backend's run generator, seeded once when the backend is made:
  one request sampled twice gives two samples, and a run repeats under the same sample seed.
- A row at temperature 0 takes the most likely allowed token (greedy) and draws nothing.

Every row is sampled on its own (`torch.multinomial` of that row's softmax at its temperature, with its
generator), on both generation paths: the backend's own loop (`decode.Picker`) and `model.generate`
(`SampleProcessor`, a logits processor that draws each row's token and leaves only it allowed, so that
generate's greedy step takes it). The two paths draw at different points (the loop takes a token the
grammar forces without drawing), so one seed gives different samples on the two paths.
"""

from __future__ import annotations

import torch
from transformers import LogitsProcessor

from .backend import SEED_RANGE, request_seed, sampling_config

__all__ = ["SEED_RANGE", "RowSampler", "SampleProcessor", "draw", "generator", "request_seed", "sampling_config"]

def generator(seed: int, device: str = "cpu") -> torch.Generator:
    """A torch generator on `device` seeded with `seed`."""
    return torch.Generator(device=device).manual_seed(seed)


class RowSampler:
    """Picks the next token of each row: greedy at temperature 0, else drawn from the row's softmax at its
    temperature with the row's generator (`generators[i]`; None at temperature 0)."""

    def __init__(self, temperatures, generators):
        self.temperatures, self.generators = list(temperatures), list(generators)

    @property
    def greedy(self) -> bool:
        """Whether no row samples."""
        return all(t <= 0 for t in self.temperatures)

    def pick(self, logits: torch.Tensor, rows=None) -> torch.Tensor:
        """The token of each logits row (`rows[k]`: the request row of logits row k; default 0..B-1)."""
        rows = range(logits.shape[0]) if rows is None else rows
        best = logits.argmax(dim=-1)
        if self.greedy:
            return best
        out = best.clone()
        for k, i in enumerate(rows):
            t = self.temperatures[i]
            if t > 0:
                out[k] = draw(logits[k], t, self.generators[i])
        return out


def draw(logits: torch.Tensor, temperature: float, gen: torch.Generator) -> torch.Tensor:
    """One token drawn from softmax(logits / temperature) with `gen` (the most likely token when no
    token is allowed at all: every logit -inf)."""
    probs = torch.softmax(logits.float() / temperature, dim=-1)
    if not bool(torch.isfinite(probs).all()):
        return logits.argmax()
    return torch.multinomial(probs, 1, generator=gen)[0]


class SampleProcessor(LogitsProcessor):
    """For `model.generate` with `do_sample=False`: draws each row's token with the row's own generator
    (`RowSampler`) after the other processors (the grammar) have masked the logits, and leaves only that
    token allowed, so that generate's greedy step takes it."""

    def __init__(self, sampler: RowSampler):
        self.sampler = sampler

    def __call__(self, input_ids: torch.Tensor, scores: torch.Tensor) -> torch.Tensor:
        picked = self.sampler.pick(scores).to(scores.device)
        out = torch.full_like(scores, float("-inf"))
        out.scatter_(1, picked.view(-1, 1), 0.0)
        return out
