"""The base student's learning curve (`adapt model curve`, training.curve): the evaluation episodes are the
split's unseen personas on the evaluation seeds, scores count dishes and satisfaction; the whole curve at a
micro scale (slow)."""

from __future__ import annotations

import json

import pytest

from .conftest import SKIP_MODELS


def test_evaluation_episodes_are_a_fixed_subset_of_unseen_personas_on_eval_seeds(domain):
    from adaptbench.training.curve import CurveSettings, eval_jobs

    s = CurveSettings(split="1", episodes=32)
    jobs = eval_jobs(domain, s)
    assert len(jobs) == 32 and jobs == eval_jobs(domain, s)  # the same at every checkpoint and size
    assert {j.persona for j in jobs} <= set(domain.unseen[1]) and {j.seed for j in jobs} <= {0, 1, 2, 3}
    assert {j.agent for j in jobs} == {"planner"}
    assert len(eval_jobs(domain, CurveSettings(split="1", episodes=1000))) == 4 * 8 * 4  # all of them


def test_scores_count_dishes_made_and_satisfaction(domain):
    from adaptbench.training.curve import scores

    recs = [{"task": "toast_coffee", "completed": ["toast"], "satisfaction_rate": 0.5, "n_steps": 50},
            {"task": "eggs", "completed": [], "satisfaction_rate": None, "n_steps": 10}]
    sc = scores(domain, recs)
    n = 2 + len(domain.task["eggs"].components)
    assert sc["dishes"] == 1 and sc["dishes_of"] == n and sc["satisfaction"] == 0.5 and sc["steps"] == 30


@pytest.mark.parametrize("sizes", ["128", "0x4", "axb", ","])
def test_a_bad_size_is_one_line(sizes, capsys, tmp_path):
    from adaptbench.cli import main

    assert main(["model", "curve", "--out", str(tmp_path / "c"), "--sizes", sizes]) == 2
    assert "--sizes" in capsys.readouterr().err


def test_training_seeds_on_the_evaluation_scenes_are_refused(capsys, tmp_path):
    from adaptbench.cli import main

    assert main(["model", "curve", "--out", str(tmp_path / "c"), "--seeds", "0-1"]) == 2
    assert "evaluation scene seeds" in capsys.readouterr().err


@pytest.mark.slow
@SKIP_MODELS
def test_a_micro_curve_at_two_sizes(tmp_path, capsys):
    """Two sizes, 4 updates, evaluated at 0, 2 and 4 updates on 2 unseen episodes of 5 steps (~1 min)."""
    from adaptbench.cli import main

    out = tmp_path / "c"
    assert main(["model", "curve", "--out", str(out), "--sizes", "32x1,48x1", "--seeds", "100", "--tasks",
                 "toast_coffee", "--steps", "4", "--every", "2", "--episodes", "2", "--max-steps", "5",
                 "--initial", "--quiet"]) == 0
    curve = json.loads((out / "curve.json").read_text())
    assert curve["split"] == "0" and curve["scene_seeds"] == [100]
    assert [s["size"] for s in curve["sizes"]] == ["h32-l1", "h48-l1"]
    for s in curve["sizes"]:
        assert [p["update"] for p in s["points"]] == [0, 2, 4]
        assert all(p["episodes"] == 2 and p["dishes_of"] == 4 for p in s["points"])
    assert {tuple(e)[0] for e in curve["eval"]} <= {"leila", "lisa", "mark", "samantha"}
    assert (out / "curve.png").stat().st_size > 0
    oracle = [json.loads(x) for x in (out / "data" / "oracle.jsonl").read_text().splitlines()]
    assert {r["agent"] for r in oracle} == {"oracle"} and not any(r["questions"] for r in oracle)
