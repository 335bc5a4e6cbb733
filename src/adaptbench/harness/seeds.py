"""Scene seeds kept apart: what a model trains on is never what it is evaluated on.

Evaluation uses scene seeds 0-3 (`EVAL_SEEDS`: the README's tables, docs/evaluation.md). Every training
command (`adapt train data`, `adapt model student`, `adapt train grpo`, the rollouts STaR-GATE learns from)
takes its scene seeds from 100 up by default (`TRAIN_SEEDS`), and refuses seeds 0-3 unless told
(`--allow-eval-seeds`). The paper gives every interaction a scene of its own; here a scene is decided by its
seed, so disjoint seeds are disjoint scenes. Training records the seeds it used (`scene_seeds` in
`summary.json`, `train.json`, `student.json`) and `adapt eval` flags a model evaluated on a scene seed it
was trained on.
"""

from __future__ import annotations

EVAL_SEEDS = (0, 1, 2, 3)
TRAIN_SEEDS = "100"  # the default --seeds of training commands (a range such as 100-103 for more)
ALLOW_FLAG = "--allow-eval-seeds"


def eval_overlap(seeds) -> list:
    """The evaluation seeds among `seeds`, sorted."""
    return sorted(set(int(s) for s in seeds) & set(EVAL_SEEDS))


def overlap_message(flag: str, seeds) -> str | None:
    """None when `seeds` avoid the evaluation seeds; else the one-line usage error naming the fix."""
    bad = eval_overlap(seeds)
    if not bad:
        return None
    lo, hi = EVAL_SEEDS[0], EVAL_SEEDS[-1]
    n = len(set(seeds))
    fix = f"100-{99 + n}" if n > 1 else "100"
    return (f"{flag} {seeds_text(bad)} meets the evaluation scene seeds {lo}-{hi}: train on scenes the student is "
            f"never evaluated on (e.g. {flag} {fix}), or pass {ALLOW_FLAG} to do it anyway")


def seeds_text(seeds) -> str:
    """Seeds as the command line writes them: 0-3, or 1,5,7."""
    s = sorted(set(int(x) for x in seeds))
    if len(s) > 1 and s == list(range(s[0], s[-1] + 1)):
        return f"{s[0]}-{s[-1]}"
    return ",".join(map(str, s))


def seen_seeds_lines(records, trained: dict) -> list:
    """Lines flagging episodes whose scene seed the model was trained on. `trained`: model directory ->
    the scene seeds of its training (`methods.trained_seeds`)."""
    hits: dict = {}
    for r in records:
        model = (r.agent_config or {}).get("model")
        seeds = trained.get(model) or ()
        if model and r.seed in seeds:
            hits.setdefault((r.agent, model), set()).add(r.seed)
    return [f"warning: {method} ({model}) was evaluated on scene seed(s) {seeds_text(s)} it was trained on: "
            f"those episodes are not held out (train from seed 100 up, evaluate on {seeds_text(EVAL_SEEDS)})"
            for (method, model), s in sorted(hits.items())]
