"""Defaults of the transformers backend on a CPU, by model size.

    settings = cpu_defaults("models/smollm2")    # CpuSettings(threads=2, dtype="bfloat16", batch=16)

A small model (the tiny test model, a few MB) gains nothing from more torch threads and runs best in
its own float32 with 16 episodes batched. A real model (SmolLM2-135M: 538 MB in float32) is measured
in docs/smollm2.md (`python bench/bench_llm.py --model models/smollm2 --settings`): each step reads a
few hundred new prompt tokens per episode (compute-bound: two threads and bfloat16 help, on a CPU with
native bfloat16 instructions) and decodes ~10 tokens (memory-bound on the weights). One row at a time
(`--batch 1`, or a run of one episode) runs as `bfloat16-weights` (float32 with packed bfloat16 linear
weights, `cpu_kernels`): plain bfloat16's attention is slow for one query row.
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


def cpu_defaults(model: str, batch: int | None = None, episodes: int | None = None) -> CpuSettings:
    """The measured-fastest settings for a model directory on this CPU (`batch`: the episodes batched, when
    given; `episodes`: how many the run has, when known). One row at a time (batch 1, or a run of one
    episode) runs a real model as `bfloat16-weights` (`cpu_kernels`: float32 with packed bfloat16 linear
    weights), where the CPU and torch have bfloat16 packing, else in its own precision: decoding one row
    in plain bfloat16 measured 2.5x slower than in float32 (SmolLM2-135M's shape, 1 thread: 3.7 against
    9.1 tokens/s, issue 29; torch's bfloat16 attention for one query row is the slow part)."""
    rows = min(batch or 16, episodes or 16)
    if weight_bytes(model) < LARGE:
        return CpuSettings(threads=1, dtype="auto", batch=batch or 16)
    threads = max(1, min(2, os.cpu_count() or 1))
    if not native_bf16():
        return CpuSettings(threads=threads, dtype="auto", batch=batch or 16)
    return CpuSettings(threads=threads, dtype="bfloat16" if rows > 1 else _one_row_dtype(), batch=batch or 16)


def _one_row_dtype() -> str:
    """`bfloat16-weights` where torch packs bfloat16 weights here, else the checkpoint's own."""
    try:
        from .cpu_kernels import BF16_WEIGHTS, packing_supported
    except ImportError:  # no torch: no transformers backend either
        return "auto"
    return BF16_WEIGHTS if packing_supported() else "auto"
