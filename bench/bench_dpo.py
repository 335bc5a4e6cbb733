"""DPO seconds per step at batch 4 on the tiny model (CPU), with and without precomputed reference
log-probs (`adapt train dpo --precompute-ref yes|no`, TRL's `precompute_ref_log_probs`): the reference is the
adapter switched off, so without precomputing every step runs a second forward pass over chosen and rejected.

    python bench/bench_dpo.py [--model DIR] [--steps 6] [--batch 4] [--threads 2]
                              # builds the (random) tiny model and a small pairs set when --model/--data are absent

Rows come from `adapt train data` (2 personas x 2 tasks of split 1 on the tiny student, built once into the
work directory); each setting trains `--steps` steps in this process from a fresh output directory. Reported:
seconds per step (the training loop only), the one-off precompute pass, the ratio, and the cost of one epoch
over the rows each way; in wall time and in this process's CPU time (on a shared machine the CPU figures are
the steadier ones).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def build_data(model: str, out: Path) -> dict:
    """Pairs from the tiny student over sarah,ron x eggs,cereal of split 1 (reused when already built)."""
    from adaptbench.cli.main import main

    if not (out / "summary.json").is_file():
        code = main(["train", "data", "--student", model, "--out", str(out), "--split", "1", "--personas",
                     "sarah,ron", "--tasks", "eggs,cereal", "--batch", "4"])
        if code:
            raise SystemExit(f"adapt train data failed ({code})")
    return json.loads((out / "summary.json").read_text())


def one(data: Path, model: str, out: Path, precompute: str, steps: int, batch: int, threads: int) -> dict:
    """Train `steps` DPO steps; the seconds of setup (loading, precompute) and per step."""
    from adaptbench.training.trainers import METHODS, train
    from adaptbench.training.trainers.config import load_settings

    shutil.rmtree(out, ignore_errors=True)
    s = load_settings(METHODS["dpo"], {"data": str(data), "model": model, "out": str(out), "max_steps": steps,
                                       "batch": batch, "precompute_ref": precompute, "threads": threads,
                                       "logging_steps": 1, "save_steps": 10_000})
    r = train("dpo", s, log=lambda m: print("  " + m, file=sys.stderr))
    return {"setup_seconds": r["setup_seconds"], "seconds_per_step": r["seconds_per_step"],
            "setup_cpu_seconds": r["setup_cpu_seconds"], "cpu_seconds_per_step": r["cpu_seconds_per_step"],
            "rows": r["rows"],
            "loss": [r["first"]["loss"], r["last"]["loss"]], "margin": r["last"].get("rewards/margins")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", help="model directory (default: the tiny model, built)")
    ap.add_argument("--data", help="an `adapt train data` output directory (default: built from the model)")
    ap.add_argument("--work", help="work directory (default: a temporary one)")
    ap.add_argument("--steps", type=int, default=6)
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    work = Path(a.work or tempfile.mkdtemp(prefix="bench_dpo_"))
    work.mkdir(parents=True, exist_ok=True)
    model = a.model
    if model is None:
        from adaptbench.compiler import load_domain
        from adaptbench.llm.tiny import init_tiny

        model = str(work / "tiny")
        if not (work / "tiny" / "config.json").is_file():
            init_tiny(load_domain(), model)
    t0 = time.perf_counter()
    data = Path(a.data) if a.data else work / "data"
    summary = build_data(model, data) if not a.data else json.loads((data / "summary.json").read_text())
    print(f"data: {summary['trainable']} trainable rows of {summary['pairs']} steps, prompt tokens "
          f"{summary['prompt_tokens']} ({time.perf_counter() - t0:.0f} s)")
    got = {k: one(data, model, work / f"dpo_{k}", k, a.steps, a.batch, a.threads) for k in ("no", "yes")}
    plain, pre = got["no"], got["yes"]
    epoch = -(-plain["rows"] // a.batch)
    out = {"batch": a.batch, "steps": a.steps, "rows": plain["rows"], "without_precompute": plain,
           "with_precompute": pre}
    for kind, step, setup in (("wall", "seconds_per_step", "setup_seconds"),
                              ("cpu", "cpu_seconds_per_step", "setup_cpu_seconds")):
        extra = pre[setup] - plain[setup]
        out[kind] = {"step_ratio": round(plain[step] / pre[step], 2), "precompute_pass_seconds": round(extra, 2),
                     "one_epoch_seconds": {"without": round(epoch * plain[step], 1),
                                           "with": round(epoch * pre[step] + extra, 1)}}
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
