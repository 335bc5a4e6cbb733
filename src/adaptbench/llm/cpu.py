"""Defaults of the transformers backend on a CPU, by model size.

    settings = cpu_defaults("models/smollm2")    # CpuSettings(threads=2, dtype="bfloat16", batch=16)

A small model (the tiny test model, a few MB) gains nothing from more torch threads and runs best in
its own float32 with 16 episodes batched. A real model (SmolLM2-135M: 538 MB in float32) is measured
in docs/smollm2.md (`python bench/bench_llm.py --model models/smollm2 --settings`): each step reads a
few hundred new prompt tokens per episode (compute-bound: two threads and bfloat16 help, on a CPU with
native bfloat16 instructions) and decodes ~10 tokens (memory-bound on the weights; bfloat16 pays off
only when 16 rows share each pass: one episode at a time, `--batch 1`, stays in its own precision).
`--dtype`, `--batch` given on the command line win.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

LARGE = 100 * 2**20  # bytes of weights from which a model is "real-sized" (the tiny model is ~2 MB)


@dataclass(frozen=True)
class CpuSettings:
    """Torch threads, load dtype and episodes batched."""

    threads: int
    dtype: str
    batch: int


def weight_bytes(model: str) -> int:
    """Bytes of the weight files of a model directory (0 when it holds none)."""
    d = Path(model)
    if not d.is_dir():
        return 0
    return sum(f.stat().st_size for pat in ("*.safetensors", "*.bin") for f in d.glob(pat))


@lru_cache(maxsize=1)
def native_bf16() -> bool:
    """Whether the CPU has bfloat16 instructions (AVX512-BF16 or AMX; Linux /proc/cpuinfo)."""
    try:
        flags = Path("/proc/cpuinfo").read_text()
    except OSError:
        return False
    return any(f in flags.split() for f in ("avx512_bf16", "amx_bf16"))


def cpu_defaults(model: str, batch: int | None = None) -> CpuSettings:
    """The measured-fastest settings for a model directory on this CPU (`batch`: the episodes batched, when
    given). One episode at a time keeps a real model in its own precision: decoding one row in bfloat16
    measured 2.5x slower than in float32 (SmolLM2-135M's shape, 1 thread: 3.7 against 9.1 tokens/s,
    issue 29), and a step decodes more than it gains in reading its new turn faster."""
    if weight_bytes(model) < LARGE:
        return CpuSettings(threads=1, dtype="auto", batch=batch or 16)
    bf16 = native_bf16() and batch != 1
    return CpuSettings(threads=max(1, min(2, os.cpu_count() or 1)), dtype="bfloat16" if bf16 else "auto",
                       batch=batch or 16)
