"""Anchor episodes: a teacher's whole episodes trained beside a method's rows (`--anchor FILES`).

Every LoRA training of the CPU students that moved them far enough to change when they ask also broke
their long recipes (docs/training.md: 150-240 updates lose the eggs and the omelettes). The rows train
single steps; nothing in them says "and then finish the omelette". An anchor keeps the recipes the way
language-model RLHF keeps the pretraining distribution (InstructGPT's PPO-ptx): each update adds, to the
method's own loss, `--anchor-weight` times the mean token loss of `--anchor-per-update` of a teacher's whole
episodes (rendered with the planner prompt and packed as `adapt model pretrain` packs them: the loss on
every action).

    stream = AnchorStream.load(domain, ["runs/oracle-ask.jsonl"], tokenizer, seed=0)
    ids, labels = stream.take(3)        # the sequence of the 3rd episode of the seeded order

Episodes are replayed and tokenized when first used (a run of 150 updates reads 150-300 of them, not the
file's thousands), in an order fixed by the seed, indexed by the update: a run resumed from a checkpoint
goes on with the episodes it would have seen. Off by default: the paper's Algorithm 1 trains on the rows
alone.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field
from pathlib import Path

from .run import TrainError


def anchor_paths(spec: str) -> list:
    """The JSONL files named by `--anchor` (comma-separated files or directories of them); TrainError
    naming a path that does not exist or holds none."""
    paths = []
    for part in (p.strip() for p in spec.split(",")):
        if not part:
            continue
        p = Path(part)
        found = sorted(p.glob("*.jsonl")) if p.is_dir() else [p] if p.is_file() else []
        if not found:
            raise TrainError(f"--anchor {part}: no such file, or a directory with no .jsonl file in it", code=2)
        paths += found
    return paths


@dataclass
class AnchorStream:
    """A seeded, endless order over a teacher's episode records; `take(i)` is the i-th sequence of it."""

    domain: object
    records: list
    tokenizer: object
    seed: int = 0
    _order: list = field(default_factory=list)
    _cache: dict = field(default_factory=dict)
    skipped: int = 0

    @classmethod
    def load(cls, domain, paths, tokenizer, seed: int = 0) -> AnchorStream:
        """The stream over every finished episode record in `paths` (TrainError when there is none)."""
        from ..pretrain import read_records

        records = read_records(paths)
        if not records:
            raise TrainError(f"--anchor {', '.join(map(str, paths))}: no episode records (adapt rollout's lines) in it",
                             code=2)
        return cls(domain, records, tokenizer, seed)

    def seeds(self) -> set:
        """The scene seeds of the records (checked against the evaluation's like the rows')."""
        return {r.get("seed") for r in self.records if isinstance(r.get("seed"), int)}

    def personas(self) -> list:
        """The personas of the records, sorted (recorded in train.json)."""
        return sorted({str(r.get("persona")) for r in self.records})

    def take(self, i: int) -> tuple:
        """The `(ids, labels)` of the i-th episode in the seeded order (passes reshuffled each time round); an
        episode whose replay differs from its record is passed over (counted in `skipped`)."""
        for _ in range(len(self.records)):
            seq = self._sequence(self._index(i))
            if seq is not None:
                return seq
            i += 1
        raise TrainError("--anchor: no episode of it replays with this spec", code=2)

    def _index(self, i: int) -> int:
        n = len(self.records)
        while len(self._order) <= i:
            rng = random.Random(f"{self.seed}:{len(self._order) // n}")
            self._order += rng.sample(range(n), n)
        return self._order[i]

    def _sequence(self, k: int):
        if k not in self._cache:
            from ...llm.prompts import PromptBuilder
            from ..pretrain import packed_example, replay_views

            steps = replay_views(self.domain, self.records[k])
            packed = packed_example(PromptBuilder(self.domain, "planner"), self.tokenizer, steps, None)[0] \
                if steps else None
            self.skipped += packed is None
            self._cache[k] = packed
        return self._cache[k]


def check_anchor_seeds(stream: AnchorStream, s) -> None:
    """TrainError (exit 2) when the anchor's episodes are on the evaluation scene seeds, unless
    `--allow-eval-seeds`, as for the rows."""
    from ...harness.seeds import ALLOW_FLAG, eval_overlap, seeds_text

    bad = eval_overlap(tuple(sorted(stream.seeds())))
    if bad and not s.allow_eval_seeds:
        raise TrainError(f"--anchor {s.anchor} holds episodes on the evaluation scene seeds {seeds_text(bad)}: anchor "
                         f"on a teacher's episodes from training scenes (`adapt rollout --agent oracle-ask --seeds "
                         f"130-169` on the split's training personas), or pass {ALLOW_FLAG}", code=2)


def anchored(trainer_class, stream: AnchorStream, per_update: int, weight: float):
    """`trainer_class` whose training loss adds `weight` × the mean token loss of `per_update` anchor episodes
    per forward (each micro-batch of a gradient accumulation takes its own); logged as `anchor_loss`."""

    class Anchored(trainer_class):
        def compute_loss(self, model, inputs, return_outputs=False, num_items_in_batch=None):
            out = super().compute_loss(model, inputs, return_outputs=return_outputs,
                                       num_items_in_batch=num_items_in_batch)
            if not model.training:
                return out
            extra = self._anchor_loss(model)
            self._anchor_seen.append(float(extra.detach()))
            if return_outputs:
                return out[0] + weight * extra, out[1]
            return out + weight * extra

        def _anchor_loss(self, model):
            import torch

            if getattr(self, "_anchor_next", None) is None:  # a resumed run goes on where its steps left it
                self._anchor_next = self.state.global_step * self.args.gradient_accumulation_steps * per_update
                self._anchor_seen = []
            parts = []
            for _ in range(per_update):
                ids, labels = stream.take(self._anchor_next)
                self._anchor_next += 1
                dev = model.device if hasattr(model, "device") else None
                parts.append(model(input_ids=torch.tensor([ids], device=dev),
                                   labels=torch.tensor([labels], device=dev)).loss)
            return torch.stack(parts).mean()

        def log(self, logs, *args, **kwargs):
            seen = getattr(self, "_anchor_seen", None)
            if seen and "loss" in logs:
                logs["anchor_loss"] = round(sum(seen) / len(seen), 4)
                self._anchor_seen = []
            return super().log(logs, *args, **kwargs)

    Anchored.__name__ = f"Anchored{trainer_class.__name__}"
    return Anchored
