"""`adapt eval --paired METHOD`: every method's satisfaction minus METHOD's on the same (split, persona, task,
scene seed), mean ± standard error of the per-episode difference clustered by scene, seen and unseen apart; sample seeds of one
episode averaged; an unknown METHOD is one line and exit 2."""

from __future__ import annotations

import json
import math

import pytest

from adaptbench.cli import main
from adaptbench.harness.paired import paired, render_markdown, render_text
from adaptbench.harness.record import EpisodeRecord

UNSEEN = {0: ("leila", "lisa"), 1: ("juan", "mark")}


def _rec(agent, persona, rate, seed=0, task="eggs", split=0, **kw) -> EpisodeRecord:
    return EpisodeRecord.from_dict({"agent": agent, "persona": persona, "task": task, "seed": seed, "split": split,
                                    "satisfaction_rate": rate, "questions": 0, **kw})


def test_differences_are_taken_episode_by_episode():
    base = [_rec("planner", "leila", 0.2, seed=s) for s in range(4)] + [_rec("planner", "juan", 0.5)]
    dpo = [_rec("reflection-dpo", "leila", r, seed=s) for s, r in enumerate((0.4, 0.2, 0.6, 0.0))]
    dpo += [_rec("reflection-dpo", "juan", 1.0), _rec("reflection-dpo", "lisa", 1.0)]  # lisa: the base has no such episode
    rows = paired(base + dpo, "planner", UNSEEN)
    assert [(r.method, r.column, r.n) for r in rows] == [("reflection-dpo", "seen", 1), ("reflection-dpo", "unseen", 4)]
    unseen = rows[1]
    diffs = [0.2, 0.0, 0.4, -0.2]
    mean = sum(diffs) / 4
    se = math.sqrt(sum((d - mean) ** 2 for d in diffs) / 3 / 4)
    assert unseen.mean == pytest.approx(mean) and unseen.se == pytest.approx(se)
    assert (unseen.better, unseen.worse, unseen.same) == (2, 1, 1)
    assert unseen.clear is False  # 0.1 against 2 x 0.129
    assert rows[0].mean == pytest.approx(0.5) and rows[0].clear is False  # one episode: no standard error to judge by


def test_splits_pair_with_their_own_base_and_sample_seeds_are_averaged():
    recs = [_rec("planner", "leila", 0.0, split=0), _rec("planner", "leila", 0.5, split=1),
            _rec("no-dpo", "leila", 0.5, split=0), _rec("no-dpo", "leila", 0.5, split=1),
            _rec("sampled", "leila", 0.2, split=0, sample_seed=0), _rec("sampled", "leila", 0.6, split=0, sample_seed=1)]
    rows = {(r.method, r.column): r for r in paired(recs, "planner", UNSEEN)}
    assert rows["no-dpo", "unseen"].n == 1 and rows["no-dpo", "unseen"].mean == pytest.approx(0.5)  # split 0 vs 0
    assert rows["no-dpo", "seen"].mean == pytest.approx(0.0)  # split 1 (leila seen there) vs split 1's base
    assert rows["sampled", "unseen"].n == 1 and rows["sampled", "unseen"].mean == pytest.approx(0.4)


def test_a_clear_gain_and_the_rendered_tables():
    recs = [_rec("planner", "leila", 0.2, seed=s) for s in range(20)]
    recs += [_rec("reflection-dpo", "leila", 0.5 + (0.05 if s % 2 else -0.05), seed=s) for s in range(20)]
    rows = paired(recs, "planner", UNSEEN)
    assert rows[0].clear and rows[0].mean == pytest.approx(0.3)
    text = render_text(rows, "planner")
    assert "Paired with planner" in text and "+30.0 ± 1.1" in text and "20 / 0 / 0" in text and "yes" in text
    assert render_markdown(rows, "planner").count("|") > 10
    assert "no episode in common" in render_text([], "planner")


def test_cli_paired_and_an_unknown_method(tmp_path, capsys):
    path = tmp_path / "runs.jsonl"
    recs = [{"agent": a, "persona": "juan", "task": "eggs", "seed": s, "satisfaction_rate": r, "questions": 0,
             "max_steps": 50} for s in range(3) for a, r in (("planner", 0.25), ("always-ask", 0.75))]
    path.write_text("".join(json.dumps(r) + "\n" for r in recs))
    assert main(["eval", str(path), "--paired", "planner", "--no-ceiling"]) == 0
    out = capsys.readouterr().out
    assert "Paired with planner" in out and "always-ask" in out and "+50.0 ± 0.0" in out
    md = tmp_path / "t.md"
    assert main(["eval", str(path), "--paired", "planner", "--no-ceiling", "--markdown", str(md)]) == 0
    assert "Paired with planner" in md.read_text()
    capsys.readouterr()
    assert main(["eval", str(path), "--paired", "dpo", "--no-ceiling"]) == 2
    captured = capsys.readouterr()
    assert "Table 1" not in captured.out  # refused before any table
    err = [line for line in captured.err.strip().splitlines() if "predate" not in line]
    assert len(err) == 1 and "--paired dpo" in err[0] and "always-ask, planner" in err[0]


def test_personas_of_one_scene_are_not_independent_draws():
    """The standard error is clustered by scene (split, task, seed): four personas that share a scene, and
    a model that acts the same for all of them, count as one draw, not four."""
    personas = ("leila", "lisa", "mark", "samantha")
    diffs = {0: 0.4, 1: 0.0, 2: 0.2, 3: -0.2}  # one difference per scene, shared by its four personas
    recs = [_rec("planner", p, 0.2, seed=s) for p in personas for s in diffs]
    recs += [_rec("sft", p, 0.2 + d, seed=s) for p in personas for s, d in diffs.items()]
    unseen = {0: personas}
    row = paired(recs, "planner", unseen)[0]
    assert (row.n, row.scenes) == (16, 4) and row.mean == pytest.approx(0.1)
    per_scene = math.sqrt(sum((d - 0.1) ** 2 for d in diffs.values()) / 3 / 4)  # four draws, not sixteen
    assert row.se == pytest.approx(per_scene)
    one_scene = [r for r in recs if r.seed == 0]
    row = paired(one_scene, "planner", unseen)[0]
    assert (row.n, row.scenes, row.se) == (4, 1, 0.0) and not row.clear  # no spread to judge a difference by
    assert "Scenes" in render_text(paired(recs, "planner", unseen), "planner")
