"""Reflection-DPO's data side on the tiny model (CPU): pairs built per minute by `adapt train data`'s builder
with where the time goes (student generation, teacher relabelling, reflection, scoring), and the scoring
throughput of the backend's batched `score` (16 action texts in one call) against one text per call.

    python bench/bench_reflection_data.py [--model DIR] [--personas sarah,ron] [--tasks eggs]
                                          # builds the (random) tiny model when --model is absent
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def scoring(backend, domain, n: int = 16, reps: int = 3) -> dict:
    """Action texts scored per second: one batched call versus one call per text (same prompt)."""
    from tests.llm.conftest import play

    from adaptbench.training.relabel import student_policy

    student = student_policy(backend, domain)
    ep, _ = play(domain)
    student.start(ep.id, ep.env)
    from adaptbench.llm.chat import render

    x = render(backend.tokenizer, student.act_batch([ep.view()])[0].prompt)
    texts = [f"Move egg_{i} to pan_0" if i % 2 else f"Look for item {i}" for i in range(n)]
    backend.score(x, texts[:2])  # warm up
    t0 = time.perf_counter()
    for _ in range(reps):
        backend.score(x, texts)
    batched = n * reps / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    for _ in range(reps):
        for t in texts:
            backend.score(x, [t])
    single = n * reps / (time.perf_counter() - t0)
    return {"batched_per_s": round(batched, 1), "single_per_s": round(single, 1), "ratio": round(batched / single, 2)}


def pairs(backend, domain, model: str, personas, tasks, out: Path, every_step: bool = False) -> dict:
    """Steps considered and trainable pairs per minute, and the seconds per phase. `every_step`: also
    reflect on and score steps after two failures (a random tiny student fails at every step, so otherwise
    nothing reaches reflection; this measures what each step costs on the full path)."""
    from adaptbench.training.data import Builder, DataSettings
    from adaptbench.training.dataset import PairStore
    from adaptbench.training.relabel import student_policy

    student = student_policy(backend, domain)
    store = PairStore(out)
    cls = Builder
    if every_step:
        class EveryStep(Builder):
            def _skip(self, r, student, teacher):
                reason = super()._skip(r, student, teacher)
                return None if reason == "after_two_failures" else reason
        cls = EveryStep
    b = cls(domain, student, DataSettings(None, personas, tasks), store, model)
    t0 = time.perf_counter()
    b.run()
    wall = time.perf_counter() - t0
    trainable = sum(r["kind"] in ("question", "teacher") for r in store.rows)
    secs = b.times.seconds
    return {"steps": len(store.rows), "trainable": trainable, "wall_s": round(wall, 1),
            "steps_per_min": round(60 * len(store.rows) / wall, 1), "pairs_per_min": round(60 * trainable / wall, 1),
            "seconds": {k: round(v, 2) for k, v in secs.items()},
            "teacher_share": round(secs["teacher"] / max(sum(secs.values()), 1e-9), 3)}


def main() -> None:
    """Run both measurements and print them as JSON."""
    import json

    from adaptbench.compiler import load_domain
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.paper import default_spec

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--model")
    ap.add_argument("--personas", default="sarah,ron")
    ap.add_argument("--tasks", default="eggs")
    args = ap.parse_args()
    domain = load_domain(default_spec())
    with tempfile.TemporaryDirectory() as tmp:
        model = args.model
        if model is None:
            from adaptbench.llm.tiny import init_tiny

            model = str(init_tiny(domain, Path(tmp) / "tiny"))
        backend = TransformersBackend(model, batch_size=16, dtype="float32")
        out = {"scoring": scoring(backend, domain),
               "pairs": pairs(backend, domain, model, tuple(args.personas.split(",")), tuple(args.tasks.split(",")),
                              Path(tmp) / "data"),
               "pairs_every_step": pairs(backend, domain, model, tuple(args.personas.split(",")),
                                         tuple(args.tasks.split(",")), Path(tmp) / "data2", every_step=True)}
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
