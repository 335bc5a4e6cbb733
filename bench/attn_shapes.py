"""Decode attention of a graphed pass, timed per variant on a GPU (issue 29): SDPA as dispatched (cuDNN on
an H100/H200), SDPA's memory-efficient and math kernels, and a plain matmul-softmax-matmul, at the
135M shape's decode sizes (64 rows, 3 key/value heads x 3 folded queries, head dim 64), each captured in
a CUDA graph of 30 calls (one pass's layers) and replayed.

    python bench/attn_shapes.py [--device cuda] [--rows 64] [--lengths 1024,2048,4096]
"""

from __future__ import annotations

import argparse
import time

import torch
import torch.nn.functional as F
from torch.nn.attention import SDPBackend, sdpa_kernel


def _manual(q, k, v, bias, scale):
    s = torch.matmul(q, k.transpose(-1, -2)).mul_(scale).add_(bias)
    return torch.matmul(torch.softmax(s, dim=-1), v)


def _variants():
    def sdpa(q, k, v, bias, scale):
        return F.scaled_dot_product_attention(q, k, v, attn_mask=bias, scale=scale)

    def only(backend):
        def run(q, k, v, bias, scale):
            with sdpa_kernel([backend]):
                return F.scaled_dot_product_attention(q, k, v, attn_mask=bias, scale=scale)
        return run

    return {"sdpa": sdpa, "efficient": only(SDPBackend.EFFICIENT_ATTENTION), "math": only(SDPBackend.MATH),
            "cudnn": only(SDPBackend.CUDNN_ATTENTION), "manual": _manual}


def _time(fn, args, device, calls: int = 30, reps: int = 50) -> float:
    """Microseconds per call."""
    if device.type != "cuda":
        t0 = time.perf_counter()
        for _ in range(reps):
            fn(*args)
        return (time.perf_counter() - t0) / reps * 1e6
    stream = torch.cuda.Stream()
    stream.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(stream):
        fn(*args)
    torch.cuda.current_stream().wait_stream(stream)
    graph = torch.cuda.CUDAGraph()
    with torch.cuda.graph(graph):
        for _ in range(calls):
            fn(*args)
    graph.replay()
    torch.cuda.synchronize()
    start, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
    start.record()
    for _ in range(reps):
        graph.replay()
    end.record()
    torch.cuda.synchronize()
    return start.elapsed_time(end) * 1000 / (reps * calls)


def main() -> None:
    """Print microseconds per attention call for each variant and length."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--rows", type=int, default=64)
    ap.add_argument("--lengths", default="1024,2048,4096")
    ap.add_argument("--new", type=int, default=1, help="new tokens a row (1: a decoding pass)")
    args = ap.parse_args()
    dev = torch.device(args.device)
    dtype = torch.bfloat16 if dev.type == "cuda" else torch.float32
    kv, groups, d = 3, 3, 64
    for length in (int(x) for x in args.lengths.split(",")):
        q = torch.randn(args.rows, kv, groups * args.new, d, device=dev, dtype=dtype)
        k = torch.randn(args.rows, kv, length, d, device=dev, dtype=dtype)
        v = torch.randn_like(k)
        keep = torch.rand(args.rows, 1, 1, length, device=dev) > 0.2
        bias = torch.where(keep, 0.0, torch.finfo(dtype).min).to(dtype).expand(args.rows, 1, groups * args.new,
                                                                              length)
        ref = _manual(q.float(), k.float(), v.float(), bias.float(), d ** -0.5)
        for name, fn in _variants().items():
            try:
                out = fn(q, k, v, bias, d ** -0.5)
                err = (out.float() - ref).abs().max().item()
                us = _time(fn, (q, k, v, bias, d ** -0.5), dev)
                print(f"length {length:5d}  {name:9s} {us:8.1f} us/call  max err {err:.3g}", flush=True)
            except Exception as exc:  # noqa: BLE001 - a backend that refuses these shapes is reported
                print(f"length {length:5d}  {name:9s} refused: {str(exc).splitlines()[0][:100]}", flush=True)


if __name__ == "__main__":
    main()
