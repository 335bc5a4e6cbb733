"""`adapt model ship`: a model trained by `adapt train reproduce` made a named model of the package, with its
provenance (`--model student-rdpo` is Reflection-DPO from the shipped base student, docs/training.md).

    rec = ship(Path("runs/r0"), "dpo", Path("src/adaptbench/checkpoints/student-rdpo"))

From the pipeline's OUT it copies the method's merged model (the model and tokenizer files only) and writes
`training.json` beside them: the method and split (what `adapt eval` reads to label the rows and count the
split's held-out personas as unseen), every scene seed the model and its base were trained on (so `adapt
eval` flags an evaluation on one of them), the base student's record, the training data's summary, the
trainer's settings and result, and the evaluation the pipeline ran: each row's satisfaction and dishes, and
the method against the base planner on the same episodes (the standard error clustered by scene). Nothing
is shipped from a run whose method has not finished training (no train.json), and a refused ship leaves the
destination as it was.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from ..harness.methods import PROVENANCE  # training.json: adapt eval reads method and split from it
from .pretrain import file_sha256

MODEL_FILES = ("config.json", "generation_config.json", "model.safetensors", "tokenizer.json",
               "tokenizer_config.json", "chat_template.jinja", "special_tokens_map.json")
REFERENCE = "planner"  # the base student's row the method is paired with


class ShipError(ValueError):
    """A run that cannot be shipped; the message says what is missing."""


def trained_dir(run: Path, method: str) -> Path:
    """The trainer's output folder of `method` in a reproduce run (star-gate's sits under star-gate/model)."""
    return run / "star-gate" / "model" if method == "star-gate" else run / method


def _json(path: Path) -> dict:
    """The JSON object in `path`; ShipError when it is missing or unreadable."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ShipError(f"{path} is missing") from None
    except (OSError, ValueError) as exc:
        raise ShipError(f"cannot read {path} ({exc})") from None


def _row(r: dict) -> dict:
    def pct(ms):
        return None if ms[0] is None else [round(100 * ms[0], 2), round(100 * ms[1], 2)]

    return {"episodes": r["episodes"], "satisfaction_seen": pct(r["rate_seen"]),
            "satisfaction_unseen": pct(r["rate_unseen"]), "questions_unseen": r["questions_unseen"][0]}


def evaluation(run: Path, method: str, domain) -> dict:
    """The pipeline's evaluation of `method` beside the base planner's (percentages, mean and standard
    error), dishes made, and the paired difference per column; {} when either results file is missing."""
    from ..harness.evaluate import load_records, table
    from ..harness.methods import Resolver, method_name
    from ..harness.paired import paired

    files = {"base": run / "eval" / "base.jsonl", method: run / "eval" / f"{method}.jsonl"}
    if not all(f.is_file() for f in files.values()):
        return {}
    name = method_name(method)
    records = []
    for key, path in files.items():
        resolver = Resolver({str(path.resolve()): (name, None)} if key != "base" else {})
        records += [resolver.resolve(r, str(path)) for r in load_records([path])]
    records = [r for r in records if r.agent in (REFERENCE, name)]
    rows = {r["agent"]: _row(r) for r in table(records, domain.unseen)}
    for r in records:
        rows[r.agent]["dishes"] = rows[r.agent].get("dishes", 0) + len(r.completed or ())
    pairs = [{"personas": p.column, "episodes": p.n, "scenes": p.scenes,
              "difference": [round(100 * p.mean, 2), round(100 * p.se, 2)], "clear": p.clear,
              "better_worse_same": [p.better, p.worse, p.same]}
             for p in paired(records, REFERENCE, domain.unseen) if p.method == name]
    return {"files": {k: str(v) for k, v in files.items()}, "rows": rows, "paired_with_base": pairs,
            "settings": "greedy, 50 steps, the offline user; paired on the same (split, persona, task, scene "
                        "seed), standard error clustered by scene"}


def provenance(run: Path, method: str, name: str, domain) -> dict:
    """What `training.json` records for `method` of the reproduce run `run` (ShipError when the method has
    not finished training)."""
    out = trained_dir(run, method)
    train = _json(out / "train.json")
    settings = _json(out / "settings.json")
    given = _json(run / "base" / "done.json").get("given")  # --base DIR: its path, hash and student.json
    student = given["student"] if given else _json(run / "base" / "student.json")
    base = given or {"base": str(run / "base"), "student": student}
    seeds = sorted({*train.get("scene_seeds", ()), *student.get("scene_seeds", ())})
    data = run / "pairs" / "summary.json"
    return {"name": name, "method": train.get("method", method), "split": train.get("split", student.get("split")),
            "scene_seeds": seeds, "base": base, "data": _json(data) if method != "star-gate" else None,
            "settings": settings, "train": train, "evaluation": evaluation(run, method, domain),
            "built_by": f"adapt train reproduce (OUT={run}), then adapt model ship --run {run} --method {method} "
                        f"--name {name}"}


def ship(run: Path, method: str, dest: Path, name: str, domain, log=print) -> dict:
    """Copy `method`'s merged model of the reproduce run `run` to `dest` with its `training.json`; returns
    the provenance. The destination is replaced only once everything is ready."""
    src = trained_dir(run, method) / "merged"
    if not (src / "model.safetensors").is_file():
        raise ShipError(f"{src} holds no model.safetensors (has `{method}` finished training in {run}?)")
    rec = provenance(run, method, name, domain)
    tmp = dest.with_name(dest.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    for f in MODEL_FILES:
        if (src / f).is_file():
            shutil.copyfile(src / f, tmp / f)
    rec["weights_sha256"] = file_sha256(tmp / "model.safetensors")
    (tmp / PROVENANCE).write_text(json.dumps(rec, indent=1) + "\n", encoding="utf-8")
    if dest.exists():
        shutil.rmtree(dest)
    tmp.replace(dest)
    log(f"shipped {method} of {run} as {name}: {dest} ({sum(f.stat().st_size for f in dest.iterdir()) / 1e6:.1f} MB)")
    return rec
