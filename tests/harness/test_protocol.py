"""The fair protocol (issue 27): one step budget per table (scripted agents included, recorded with every
episode, mixed budgets refused, the oracle's ceiling at the same budget), and scene seeds kept apart (a model
evaluated on a seed it trained on is flagged)."""

from __future__ import annotations

import json
import subprocess
import sys

from adaptbench.cli import main


def _adapt(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "adaptbench.cli", *args], capture_output=True, text=True,
                          timeout=300, cwd=cwd)


def _rollout(out, agent, steps=None, tasks="eggs", personas="juan,ron", seeds="0"):
    args = ["rollout", "--agent", agent, "--personas", personas, "--tasks", tasks, "--seeds", seeds,
            "--out", str(out), "--quiet"]
    assert main([*args, *(["--max-steps", str(steps)] if steps else [])]) == 0


def test_scripted_agents_stop_at_max_steps_and_record_their_budget(tmp_path):
    short, full = tmp_path / "short.jsonl", tmp_path / "full.jsonl"
    _rollout(short, "oracle,never-ask", steps=5, tasks="eggs,omelette")
    _rollout(full, "oracle,never-ask", tasks="eggs,omelette")
    cut = [json.loads(x) for x in short.read_text().splitlines()]
    whole = [json.loads(x) for x in full.read_text().splitlines()]
    assert all(r["n_steps"] <= 5 and r["agent_config"]["max_steps"] == 5 for r in cut)
    assert all(r["agent_config"]["max_steps"] == 50 for r in whole) and max(r["n_steps"] for r in whole) > 5
    oracle_cut = [r for r in cut if r["agent"] == "oracle"]
    assert all(r["satisfaction_rate"] < 1 for r in oracle_cut if r["satisfaction_rate"] is not None)  # 5 steps: no eggs


def test_eval_refuses_a_table_of_mixed_budgets_unless_asked(tmp_path, capsys):
    a, b = tmp_path / "a.jsonl", tmp_path / "b.jsonl"
    _rollout(a, "oracle", steps=20)
    _rollout(b, "never-ask")
    done = _adapt("eval", str(a), str(b))
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1
    assert "different step budgets (20 steps: oracle; 50 steps: never-ask)" in done.stderr
    assert "--max-steps" in done.stderr and "--allow-mixed" in done.stderr
    ok = _adapt("eval", str(a), str(b), "--allow-mixed")
    assert ok.returncode == 0 and " 20 " in ok.stdout and " 50 " in ok.stdout


def test_eval_shows_each_rows_budget_and_computes_the_oracle_ceiling_at_it(tmp_path):
    runs = tmp_path / "never.jsonl"
    _rollout(runs, "never-ask", steps=15, tasks="eggs,cereal")
    done = _adapt("eval", str(runs), "--csv", str(tmp_path / "t.csv"))
    assert done.returncode == 0, done.stderr
    assert "oracle computed by `adapt eval` at the same 15-step budget on the same 4" in done.stdout
    rows = {r["agent"]: r for r in __import__("csv").DictReader((tmp_path / "t.csv").open())}
    assert rows["oracle"]["max_steps"] == rows["never-ask"]["max_steps"] == "15"
    assert float(rows["oracle"]["rate_seen"]) < 1.0  # at 15 steps even the oracle makes no eggs
    plain = _adapt("eval", str(runs), "--no-ceiling")
    assert "oracle" not in plain.stdout.split("Other methods")[0].split("teacher")[1].split("\n")[0]


def test_eval_flags_a_model_evaluated_on_scene_seeds_it_trained_on(tmp_path):
    model = tmp_path / "m"
    model.mkdir()
    (model / "training.json").write_text(json.dumps({"method": "dpo", "split": 0, "scene_seeds": [1, 100]}))
    rec = {"version": 4, "agent": "planner", "agent_config": {"agent": "planner", "model": str(model), "user": "offline",
                                                               "max_steps": 50},
           "persona": "lisa", "task": "eggs", "seed": 1, "satisfaction_rate": 0.5, "questions": 0, "steps": [],
           "preferences": [], "completed": []}
    runs = tmp_path / "r.jsonl"
    runs.write_text(json.dumps(rec) + "\n" + json.dumps({**rec, "seed": 2}) + "\n")
    done = _adapt("eval", str(runs), "--no-ceiling")
    assert done.returncode == 0, done.stderr
    assert f"reflection-dpo ({model}) was evaluated on scene seed(s) 1 it was trained on" in done.stdout
