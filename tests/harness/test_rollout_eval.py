"""Rollouts write as they go and resume; eval prints Table 1 with seen/unseen columns."""

from __future__ import annotations

import json

from adaptbench.cli import main
from adaptbench.harness.evaluate import mean_se, table
from adaptbench.harness.record import EpisodeRecord
from adaptbench.harness.rollout import Job, done_keys, parse_seeds, rollout

from ..conftest import SPEC


def test_parse_seeds():
    assert parse_seeds("0-3") == [0, 1, 2, 3]
    assert parse_seeds("1,5,7") == [1, 5, 7]
    assert parse_seeds("0,0,0-1") == [0, 1]


def test_rollout_appends_and_resumes(tmp_path, domain):
    persona = domain.personas[0].id
    out = tmp_path / "runs" / "never.jsonl"
    jobs = [Job("never-ask", persona, t, 0) for t in ("eggs", "cereal")]
    assert rollout(jobs[:1], out, spec=str(SPEC), progress=False).ran == 1
    # a torn last line (a killed run) is ignored and the episode re-run
    with open(out, "a") as f:
        f.write('{"agent": "never-ask", "pers')
    assert rollout(jobs, out, spec=str(SPEC), progress=False).ran == 1
    assert rollout(jobs, out, spec=str(SPEC), progress=False).ran == 0
    assert done_keys(out) == {j.key for j in jobs}
    rec = json.loads(out.read_text().splitlines()[0])
    assert rec["steps"][-1]["action"] == "Declare Done"
    assert {"preferences", "satisfaction_rate", "questions", "scene", "spec_hash", "agent_config"} <= set(rec)
    assert rec["spec_hash"] == domain.spec_hash and rec["agent_config"]["agent"] == "never-ask"


def test_table_seen_unseen_and_se(domain):
    recs = [EpisodeRecord.from_dict({"agent": "x", "persona": p, "task": "eggs", "seed": 0, "satisfaction_rate": r,
                                     "questions": q, "split": 1}) for p, r, q in (("juan", 1.0, 2), ("ron", 0.5, 4))]
    row = table(recs, domain.unseen)[0]
    assert "juan" in domain.unseen[1]
    assert row["rate_unseen"] == (1.0, 0.0) and row["rate_seen"] == (0.5, 0.0)
    assert mean_se([1.0, 0.0]) == (0.5, 0.5)


def test_cli_rollout_then_eval(tmp_path, domain, capsys):
    persona = domain.personas[0].id
    out = tmp_path / "r.jsonl"
    assert main(["rollout", "--agent", "never-ask,oracle", "--personas", persona, "--tasks", "cereal",
                 "--seeds", "0", "--out", str(out), "--quiet", "--spec", str(SPEC)]) == 0
    md = tmp_path / "t.md"
    assert main(["eval", str(out), "--markdown", str(md), "--csv", str(tmp_path / "t.csv")]) == 0
    text = capsys.readouterr().out
    assert "never-ask" in text and "oracle" in text and "Satisfaction (seen)" in text
    assert md.read_text().startswith("**Table 1**\n\n| Paper row | Method |")


def test_eval_plot_is_a_png_with_every_agent_and_persona(tmp_path):
    from adaptbench.harness.plots import draw, persona_matrix

    recs = [EpisodeRecord(a, p, "eggs", 0, satisfaction_rate=r, questions=q)
            for a, r, q in (("never-ask", 0.3, 0), ("oracle", 0.9, 0)) for p in ("juan", "ron")]
    recs.append(EpisodeRecord("oracle", "lisa", "eggs", 0, satisfaction_rate=None, questions=0))
    out = tmp_path / "t.png"
    draw(table(recs), recs, out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 5000
    personas, grid = persona_matrix(recs, ["never-ask", "oracle"])
    assert personas == ["juan", "lisa", "ron"]
    assert grid[0] == [0.3, 0.9] and grid[1] == [None, None]


def test_eval_plot_from_the_command_line(tmp_path, capsys):
    recs = [{"agent": "oracle", "persona": "juan", "task": "cereal", "seed": 0, "satisfaction_rate": 1.0,
             "questions": 0, "spec_hash": "x", "satisfied": [], "violated": []}]
    f = tmp_path / "r.jsonl"
    f.write_text("".join(__import__("json").dumps(r) + "\n" for r in recs))
    assert main(["eval", str(f), "--plot", str(tmp_path / "t.svg")]) == 0
    assert (tmp_path / "t.svg").read_text().lstrip().startswith("<?xml")
