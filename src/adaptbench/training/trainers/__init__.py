"""`adapt train dpo|sft|no-reflection|star-gate`: Reflection-DPO, its "no DPO" and "no Reflection" ablations
and the STaR-GATE baseline, with TRL and a LoRA adapter (peft). See docs/training.md.

    from adaptbench.training.trainers import METHODS, train
    s = load_settings(METHODS["dpo"], {"data": "runs/data", "model": "models/tiny", "out": "runs/dpo"})
    result = train("dpo", s)            # OUT/adapter, OUT/merged (a model directory), OUT/train.json
"""

from __future__ import annotations

from pathlib import Path

from .config import DPOSettings, NoReflectionSettings, SFTSettings, StarGateSettings

METHODS = {"dpo": DPOSettings, "sft": SFTSettings, "no-reflection": NoReflectionSettings,
           "star-gate": StarGateSettings}


def train(method: str, s, spec=None, log=None) -> dict:
    """Train `method` with settings `s` (resuming from OUT's last checkpoint); returns train.json's content.
    A run OUT already finished (train.json, `--max-steps` reached) is not trained again: its train.json
    is returned as it is; a run whose last checkpoint reached `--max-steps` (killed while saving) only
    saves its adapter, merged model and train.json."""
    import math
    import time

    from . import engine
    from .run import (
        check_resume,
        checkpoint_step,
        finished,
        last_checkpoint,
        load_tokenizer,
        prepare,
        read_data,
        report_long,
        scene_seeds,
        trim_log,
        write_settings,
    )

    log = log or engine.stderr
    out = Path(s.out)
    out.mkdir(parents=True, exist_ok=True)
    check_resume(s, out)
    done = finished(s, out)
    if done is not None:
        log(f"train {method}: {out} already holds this finished run ({done['steps']} steps, {out / 'train.json'}); "
            "nothing to do (a larger --max-steps trains on from its last checkpoint, another --out starts anew)")
        return done
    data = read_data(method, s, log)  # a bad row stops the run before anything heavy loads
    if s.threads:
        import torch

        torch.set_num_threads(s.threads)
    tok = load_tokenizer(s.model)
    p = prepare(method, s, tok, spec, log, data)
    anchor = _anchor(s, tok, spec, p)
    scene_seeds(p, s)  # refuses data on the evaluation seeds unless --allow-eval-seeds
    note = report_long(p, s, out)
    if note:
        log(f"adapt: {note}")
    resume = last_checkpoint(out)
    at = checkpoint_step(resume)
    planned = s.max_steps or math.ceil(s.epochs * engine.steps_per_epoch(s, len(p.rows)))
    if engine.is_main():
        trim_log(out, at)  # the lines of steps after the checkpoint are logged again
    if resume and at >= planned:
        log(f"train {method}: {resume} holds all {at} steps (the run stopped while saving); saving the adapter, "
            "the merged model and train.json")
        return _finish(method, s, p, out, tok, engine.from_checkpoint(resume, out), engine.IDLE)
    t0, c0 = time.perf_counter(), time.process_time()
    trainer = engine.build(method, s, p.rows, tok, out, log, anchor)
    setup, setup_cpu = time.perf_counter() - t0, time.process_time() - c0
    if trainer.accelerator.is_main_process:
        write_settings(s, out)
    pre = bool(getattr(trainer.args, "precompute_ref_log_probs", False))
    log(f"train {method}: {len(p.rows)} rows, {planned} steps at batch {s.batch}"
        + (f", {s.anchor_per_update} anchor episode(s) a forward of {len(anchor.records)}" if anchor else "")
        + (f", resuming from {resume}" if resume else "")
        + (f"; reference log-probs precomputed ({setup:.1f} s with loading)" if pre else ""))
    timing = engine.fit(trainer, resume, log)
    timing |= {"precomputed_reference": pre, "setup_seconds": round(setup, 2), "setup_cpu_seconds": round(setup_cpu, 2)}
    engine.save_adapter(trainer, out)  # every process (DeepSpeed/FSDP gather); the main one writes
    if not trainer.accelerator.is_main_process:  # the main process writes the outputs
        return {"method": recorded_method(method, s), **_counts(p), "steps": trainer.state.global_step, **timing}
    if anchor is not None:
        timing["anchor_episodes_not_replayed"] = anchor.skipped
    return _finish(method, s, p, out, tok, engine.Trained(trainer.state.global_step, trainer.state.log_history),
                   timing)


def _anchor(s, tok, spec, p):
    """The `--anchor` episodes' stream (None without it); its scene seeds join the data's (checked against the
    evaluation's, recorded in train.json) and its size and personas are recorded with the rows' counts."""
    if not s.anchor:
        return None
    from ...compiler import load_domain
    from .anchor import AnchorStream, anchor_paths, check_anchor_seeds

    stream = AnchorStream.load(load_domain(spec), anchor_paths(s.anchor), tok, s.seed)
    check_anchor_seeds(stream, s)
    p.seeds = tuple(sorted({*p.seeds, *stream.seeds()}))
    p.left_out = {**p.left_out, "anchor_episodes": len(stream.records), "anchor_personas": stream.personas()}
    return stream


def _finish(method: str, s, p, out: Path, tok, trained, timing: dict) -> dict:
    """The adapter's tokenizer, the merged model and, last (the run's done-marker), train.json."""
    from . import engine
    from .run import scene_seeds, write_result

    result = {"method": recorded_method(method, s), **_counts(p), "scene_seeds": list(scene_seeds(p, s)),
              "steps": trained.steps,
              "precomputed_reference": False, "setup_seconds": None, "setup_cpu_seconds": None, **timing,
              **engine.summary_of(trained.history)}
    engine.finish_adapter(out, tok)
    engine.merge(s.model, out / "adapter", out / "merged", tok)
    write_result(out, result)
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
