"""`adapt train data` on the tiny model (CPU): pairs built per minute and where the time goes (student
generation, teacher relabelling, reflection, scoring), for the scripted-oracle teacher (the default) and an
LLM teacher (`--teacher-model`, here the same tiny model), with the paper's two interactions, on one worker
process and on two (`--workers 2`, what a user would otherwise do by hand: split the personas over two runs).

The random tiny student fails every step, so the decision rule's "after two failures" skip would leave
nothing to reflect on; like bench_reflection_data's `pairs_every_step`, every step goes down the full path
here (the teacher relabels, the student proposes a question under the Ask rule, the user answers, three
probabilities are scored).

    python bench/bench_train_data.py [--student DIR] [--personas sarah,ron,lisa,maya] [--tasks eggs] [--max-steps 8]
                                     [--batch 2]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _every_step_builder():
    from adaptbench.training.data import Builder

    class EveryStep(Builder):
        def _skip(self, r, student, teacher):
            reason = super()._skip(r, student, teacher)
            return None if reason == "after_two_failures" else reason
    return EveryStep


def measure(domain, backend, model: str, settings, out: Path, teacher: str) -> dict:
    """One `build` run: steps and trainable pairs per minute (wall), the seconds per phase (summed over
    workers) and the teacher's share of them."""
    from adaptbench.training.data import build
    from adaptbench.training.dataset import PairStore
    from adaptbench.training.relabel import LLMTeacher, ScriptedTeacher, student_policy

    cls = _every_step_builder()
    relabeller = LLMTeacher(backend, domain, model) if teacher == "llm" else ScriptedTeacher(domain)
    store = PairStore(out)

    def make_builder(sink):
        return cls(domain, student_policy(backend, domain), settings, sink, model, relabeller)

    t0 = time.perf_counter()
    times = build(make_builder, settings, store)
    wall = time.perf_counter() - t0
    secs = times.seconds
    trainable = sum(r["kind"] in ("question", "teacher") for r in store.rows)
    return {"teacher": teacher, "workers": settings.workers, "episodes": len(store.rows) and
            len({(r["persona"], r["task"], r["seed"], r["interaction"]) for r in store.rows}),
            "steps": len(store.rows), "trainable": trainable, "wall_s": round(wall, 1),
            "steps_per_min": round(60 * len(store.rows) / wall, 1), "pairs_per_min": round(60 * trainable / wall, 1),
            "seconds": {k: round(v, 2) for k, v in secs.items()},
            "other_s": round(wall * settings.workers - sum(secs.values()), 2) if settings.workers == 1 else None,
            "teacher_share": round(secs["teacher"] / max(sum(secs.values()), 1e-9), 3)}


def main() -> None:
    """Measure the four settings and print them as JSON."""
    from adaptbench.compiler import load_domain
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.paper import default_spec
    from adaptbench.training.data import DataSettings

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--student", help="student model directory (default: the random tiny model, built here)")
    ap.add_argument("--personas", default="sarah,ron,lisa,maya")
    ap.add_argument("--tasks", default="eggs")
    ap.add_argument("--max-steps", type=int, default=8)
    ap.add_argument("--batch", type=int, default=2)
    args = ap.parse_args()
    domain = load_domain(default_spec())
    personas, tasks = tuple(args.personas.split(",")), tuple(args.tasks.split(","))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        model = args.student
        if model is None:
            from adaptbench.llm.tiny import init_tiny

            model = str(init_tiny(domain, Path(tmp) / "tiny"))
        backend = TransformersBackend(model, batch_size=16, dtype="float32")
        for teacher in ("oracle", "llm"):
            for workers in (1, 2):
                s = DataSettings(None, personas, tasks, (0,), interactions=2, questions="student", max_length=1024,
                                 width=args.batch, workers=workers, max_steps=args.max_steps)
                rows.append(measure(domain, backend, model, s, Path(tmp) / f"{teacher}{workers}", teacher))
    for teacher in ("oracle", "llm"):
        one, two = (r for r in rows if r["teacher"] == teacher)
        rows.append({"teacher": teacher, "workers_2_vs_1_steps_per_min": round(two["steps_per_min"]
                                                                            / max(one["steps_per_min"], 1e-9), 2)})
    print(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
