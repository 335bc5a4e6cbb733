"""Size-based CPU defaults of the transformers backend (llm/cpu.py) and the command line's precedence."""

from __future__ import annotations

import argparse
import os

from adaptbench.llm.cpu import LARGE, cpu_defaults, native_bf16, weight_bytes


def _model(tmp_path, size: int):
    tmp_path.mkdir(parents=True, exist_ok=True)
    with open(tmp_path / "model.safetensors", "wb") as f:  # sparse: only the size is read
        f.truncate(size)
    return str(tmp_path)


def _packs() -> bool:
    try:
        from adaptbench.llm.cpu_kernels import packing_supported
    except ImportError:  # no torch: the models extra is not installed
        return False
    return packing_supported()


def test_a_small_model_keeps_one_thread_float32_and_16_rows(tmp_path):
    s = cpu_defaults(_model(tmp_path, 2 * 2**20))
    assert (s.threads, s.dtype, s.batch) == (1, "auto", 16)
    assert cpu_defaults(str(tmp_path / "missing")).threads == 1


def test_a_real_sized_model_gets_two_threads_and_bfloat16_where_the_cpu_has_it(tmp_path):
    path = _model(tmp_path, 538_090_408)
    assert weight_bytes(path) == 538_090_408 > LARGE
    s = cpu_defaults(path)
    assert s.threads == min(2, os.cpu_count() or 1) and s.batch == 16
    assert s.dtype == ("bfloat16" if native_bf16() else "auto")
    # one row at a time: plain bfloat16 decodes one row slower; float32 with packed bfloat16 weights where
    # torch packs them here (llm/cpu_kernels.py), else the checkpoint's own precision
    one_row = "bfloat16-weights" if native_bf16() and _packs() else "auto"
    one = cpu_defaults(path, batch=1)
    assert (one.dtype, one.batch) == (one_row, 1)
    alone = cpu_defaults(path, episodes=1)  # a run of one episode decodes one row whatever its batch
    assert (alone.dtype, alone.batch) == (one_row, 16)
    assert cpu_defaults(path, batch=4, episodes=8).dtype == s.dtype


def test_the_command_line_wins(tmp_path):
    from adaptbench.cli.model import _cpu_settings

    path = _model(tmp_path, 538_090_408)
    given = argparse.Namespace(device="cpu", dtype="float32", batch=4)
    assert _cpu_settings(given, path) == {"dtype": "float32", "threads": min(2, os.cpu_count() or 1), "batch_size": 4}
    gpu = argparse.Namespace(device="cuda", dtype=None, batch=None)
    assert _cpu_settings(gpu, path) == {"dtype": "auto", "batch_size": 16}
