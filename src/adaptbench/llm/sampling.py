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

Every row is sampled on its own (one uniform number from its generator, inverted through the cumulative
distribution of its softmax at its temperature: `draw`), on both generation paths: the backend's own loop (`decode.Picker`) and `model.generate`
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
        rows = list(range(logits.shape[0]) if rows is None else rows)
        best = logits.argmax(dim=-1)
        sampled = [k for k, i in enumerate(rows) if self.temperatures[i] > 0]
        if not sampled:
            return best
        out = best.clone()
        at = torch.tensor(sampled, dtype=torch.long, device=logits.device)
        temps = torch.tensor([self.temperatures[rows[k]] for k in sampled], device=logits.device).unsqueeze(1)
        out[at] = draw(logits[at], temps, [self.generators[rows[k]] for k in sampled], best[at])
        return out


def draw(logits: torch.Tensor, temperatures: torch.Tensor, generators: list, fallback: torch.Tensor) -> torch.Tensor:
    """One token per row drawn from softmax(logits / temperature) by inverting the row's cumulative
    distribution (float64) at one uniform number from the row's own generator: an exact categorical draw,
    the row's alone whatever else is in the batch, and faster on the CPU than one batched
    `torch.multinomial` (bench/bench_sampling.py, 16 rows: 0.27x its time at a vocabulary of 4,096,
    0.69x at 49,152). A row with no allowed token (every logit -inf) takes `fallback`."""
    cdf = torch.softmax(logits.float() / temperatures, dim=-1).double().cumsum(dim=-1)
    u = torch.cat([torch.rand(1, generator=g, dtype=torch.float64, device=g.device) for g in generators])
    picked = torch.searchsorted(cdf, (u.to(cdf.device) * cdf[:, -1]).unsqueeze(1), right=True)[:, 0]
    picked = picked.clamp(max=logits.shape[1] - 1)  # a token of probability 0 is never picked: its cdf step is flat
    return torch.where(torch.isfinite(cdf[:, -1]), picked, fallback)


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
