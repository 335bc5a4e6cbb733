"""`adapt train dpo|sft|no-reflection|star-gate`: Reflection-DPO, its "no DPO" and "no Reflection" ablations
and the STaR-GATE baseline, with TRL and a LoRA adapter (peft). See docs/training.md.

    from adaptbench.training.trainers import METHODS, train
    s = load_settings(METHODS["dpo"], {"data": "runs/data", "model": "models/tiny", "out": "runs/dpo"})
    result = train("dpo", s)            # OUT/adapter, OUT/merged (a model directory), OUT/train.json
"""

from __future__ import annotations

import json
from pathlib import Path

from .config import DPOSettings, NoReflectionSettings, SFTSettings, StarGateSettings

METHODS = {"dpo": DPOSettings, "sft": SFTSettings, "no-reflection": NoReflectionSettings,
           "star-gate": StarGateSettings}


def train(method: str, s, spec=None, log=None) -> dict:
    """Train `method` with settings `s` (resuming from OUT's last checkpoint); returns train.json's content."""
    import math
    import time

    from . import engine
    from .run import (
        check_resume,
        last_checkpoint,
        load_tokenizer,
        prepare,
        report_long,
        scene_seeds,
        write_settings,
    )

    log = log or engine.stderr
    out = Path(s.out)
    out.mkdir(parents=True, exist_ok=True)
    if s.threads:
        import torch

        torch.set_num_threads(s.threads)
    tok = load_tokenizer(s.model)
    p = prepare(method, s, tok, spec)
    seeds = scene_seeds(p, s)
    note = report_long(p, s, out)
    if note:
        log(f"adapt: {note}")
    check_resume(s, out)
    resume = last_checkpoint(out)
    t0, c0 = time.perf_counter(), time.process_time()
    trainer = engine.build(method, s, p.rows, tok, out, log)
    setup, setup_cpu = time.perf_counter() - t0, time.process_time() - c0
    if trainer.accelerator.is_main_process:
        write_settings(s, out)
    pre = bool(getattr(trainer.args, "precompute_ref_log_probs", False))
    planned = s.max_steps or math.ceil(s.epochs * engine.steps_per_epoch(s, len(p.rows)))
    log(f"train {method}: {len(p.rows)} rows, {planned} steps at batch {s.batch}"
        + (f", resuming from {resume}" if resume else "")
        + (f"; reference log-probs precomputed ({setup:.1f} s with loading)" if pre else ""))
    timing = engine.fit(trainer, resume, log)
    result = {"method": recorded_method(method, s), **_counts(p), "scene_seeds": list(seeds),
              "steps": trainer.state.global_step,
              "precomputed_reference": pre,
              "setup_seconds": round(setup, 2), "setup_cpu_seconds": round(setup_cpu, 2), **timing,
              **engine.summary_of(trainer)}
    trainer.save_model(str(out / "adapter"))  # every process (DeepSpeed/FSDP gather); the main one writes
    if trainer.accelerator.is_main_process:
        tok.save_pretrained(str(out / "adapter"))
        engine.merge(s.model, out / "adapter", out / "merged", tok)
        (out / "train.json").write_text(json.dumps(result, indent=2) + "\n")
    return result


def recorded_method(method: str, s) -> str:
    """The method train.json records (and `adapt eval` reports): `teacher-sft` for star-gate's trainer run on
    scripted agents' trajectories only (`--agent oracle,oracle-ask`: a warm start imitating a teacher, not
    the STaR-GATE baseline, which learns from the student's own rollouts); `method` otherwise."""
    from ...harness.registry import registry
    from .stargate import agent_names

    if method != "star-gate":
        return method
    agents = registry()
    named = agent_names(s.agent)
    scripted = all(a in agents and agents[a].resolved_kind() == "scripted" for a in named)
    return "teacher-sft" if named and scripted else method


def _counts(p) -> dict:
    return {"rows": len(p.rows), "long_rows_left_out": len(p.long), **p.left_out,
            "rows_truncated_left": sum(r.truncated for r in p.rows),
            "rows_with_generated_rejected_ids": sum(r.generated_rejected for r in p.rows)}


__all__ = ["METHODS", "DPOSettings", "NoReflectionSettings", "SFTSettings", "StarGateSettings", "recorded_method",
           "train"]
