"""Half-batches decoded in turn, so that one lane's CPU work runs while the GPU computes the other's pass.

    parts = lanes.split(len(rows), lanes.count(model, len(rows)))        # [range(0, 32), range(32, 64)]
    readings = lanes.run([decode.steps(model, rows_k, sessions, picker_k, stopped_k, lane=k) ...])

A decoding pass of 64 rows on the H200 (the 135M shape, CUDA graphs) cost ~13 ms, of which the GPU's own
work was ~5 ms: the rest was the CPU's part of a step (reading the picked tokens, llguidance's masks and
forced tokens, the graph's launch, bookkeeping), in series with the GPU, which waited for it. Two lanes
of 32 rows break the series: while the GPU runs lane A's pass and pick, the CPU does lane B's grammar
work and queues B's pass; then it reads A's tokens, which are ready or nearly so.

Each lane is a `decode.steps` generator with its own rows, grammar processor, picker and key/value pool
(`batch_pass.graphs_of(..., lane=k)`); `run` steps them in turn. All lanes queue on one CUDA stream, so
the stream's order keeps every tensor safe (no buffer is read by one stream while another reuses it); a
lane waits only for its own tokens (`decode.Picked`: an event after their copy to pinned memory). A lane
computes exactly what a decode call of its rows alone would: the same tokens as one batch, up to the
rounding of a different batch width.

Lanes pay where the CPU's part of a step is comparable to the GPU's: `count` gives two for the graphed
passes on CUDA with at least 2 x `LANE_MIN` rows, one elsewhere (on the CPU, the model's pass is the
CPU's work, so there is nothing to overlap); ADAPT_DECODE_LANES overrides it (how the CPU tests run two).
"""

from __future__ import annotations

import os

from . import batch_pass

LANES_ENV = "ADAPT_DECODE_LANES"
LANE_MIN = 8  # the fewest rows a lane gets by default: below, one more launch a pass costs more than it hides


def count(model, rows: int) -> int:
    """How many lanes to decode `rows` rows in: ADAPT_DECODE_LANES where set (at most one a row), else 2
    for the graphed passes on CUDA with at least 2 x `LANE_MIN` rows, else 1."""
    want = os.environ.get(LANES_ENV)
    if want:
        if not want.isdigit():
            raise ValueError(f"{LANES_ENV}={want!r}: give a whole number of lanes (1: no overlap)")
        return max(1, min(int(want), rows))
    graphed = batch_pass.mode(model) == "graphs" and model.device.type == "cuda"
    return 2 if graphed and rows >= 2 * LANE_MIN else 1


def split(rows: int, lanes: int) -> list:
    """`rows` indices in `lanes` contiguous ranges whose sizes differ by at most one."""
    size, extra = divmod(rows, lanes)
    out, start = [], 0
    for k in range(lanes):
        end = start + size + (k < extra)
        out.append(range(start, end))
        start = end
    return out


def run(lanes: list) -> list:
    """Step each generator (`decode.steps`) in turn until all are done; returns their return values."""
    results = [None] * len(lanes)
    live = list(range(len(lanes)))
    while live:
        for k in list(live):
            try:
                next(lanes[k])
            except StopIteration as done:
                results[k] = done.value
                live.remove(k)
    return results
