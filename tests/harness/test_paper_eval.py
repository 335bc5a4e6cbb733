"""`adapt eval` for the paper: methods from --method / training.json / the agent, Table 1 and Table 2 with
missing rows, the paper's numbers, standard errors, the temporal curve of a known episode, and both figures
from scripted rollouts on the command line."""

from __future__ import annotations

import csv
import json
import math

import pytest

from adaptbench.cli import main
from adaptbench.compiler import load_domain
from adaptbench.harness import papertables as pt
from adaptbench.harness.batches import record
from adaptbench.harness.episode import run_episode
from adaptbench.harness.evaluate import mean_se, table
from adaptbench.harness.methods import TABLE1, TABLE2, MethodError, Resolver, mixed_models, parse_mapping
from adaptbench.harness.policy import Decision, Policy
from adaptbench.harness.record import EpisodeRecord
from adaptbench.harness.rollout import Job
from adaptbench.harness.temporal import Curve, mean_curve, replay_all, replay_curve
from adaptbench.runtime.env import make_env

from ..conftest import SMALL, SPEC


def _rec(agent, persona="juan", rate=0.5, questions=1, seed=0, task="eggs", **kw) -> EpisodeRecord:
    return EpisodeRecord.from_dict({"agent": agent, "persona": persona, "task": task, "seed": seed,
                                    "satisfaction_rate": rate, "questions": questions, **kw})


def test_mean_and_standard_error():
    m, se = mean_se([0.0, 0.5, 1.0])
    assert m == 0.5 and se == pytest.approx(0.5 / math.sqrt(3))  # sample sd 0.5, n = 3
    assert mean_se([0.25]) == (0.25, 0.0) and mean_se([]) == (None, None)


def test_method_from_mapping_provenance_or_agent(tmp_path):
    model = tmp_path / "dpo-model"
    model.mkdir()
    (model / "training.json").write_text(json.dumps({"method": "dpo", "split": 1, "base": "smollm2"}))
    res = Resolver(parse_mapping([f"sft@2={tmp_path / 'a.jsonl'}"]))
    trained = res.resolve(_rec("planner", agent_config={"agent": "planner", "model": str(model)}), str(tmp_path / "b.jsonl"))
    assert (trained.agent, trained.split) == ("reflection-dpo", 1)
    base = res.resolve(_rec("planner", agent_config={"agent": "planner", "model": str(tmp_path)}), str(tmp_path / "b.jsonl"))
    assert (base.agent, base.split) == ("planner", None)  # no training.json: the untrained baseline
    mapped = res.resolve(_rec("planner"), str(tmp_path / "a.jsonl"))
    assert (mapped.agent, mapped.split) == ("no-dpo", 2)
    recorded = res.resolve(_rec("planner", agent_config={"method": "star_gate"}, split=0), None)
    assert (recorded.agent, recorded.split) == ("star-gate", 0)  # the record's own split wins
    # the model path as the rollout command gave it, relative to the results file's folder
    rel = res.resolve(_rec("planner", agent_config={"model": "dpo-model"}), str(tmp_path / "c.jsonl"))
    assert rel.agent == "reflection-dpo"
    for bad in ("noequals", "=x.jsonl", "dpo@one=x.jsonl"):
        with pytest.raises(MethodError):
            parse_mapping([bad])
    (model / "training.json").write_text("{not json")
    with pytest.raises(MethodError, match="cannot read"):
        Resolver().resolve(_rec("planner", agent_config={"model": str(model)}), None)


def test_the_papers_numbers_are_issue_15s():
    """Satisfaction seen/unseen and questions seen/unseen as the paper (and issue 15) publish them."""
    published = {r.id: (r.paper[0][0], r.paper[1][0], r.paper[2][0], r.paper[3][0]) for r in TABLE1 + TABLE2}
    assert published == {"never-ask": (27.5, 28.6, 0.0, 0.0), "baseline": (34.7, 34.3, 2.3, 2.3),
                         "react": (36.1, 36.8, 2.3, 2.4), "star-gate": (34.1, 33.5, 2.0, 2.0),
                         "reflection-dpo": (44.1, 42.9, 9.8, 9.5), "always-ask": (52.1, 50.8, 22.2, 22.4),
                         "teacher": (65.5, 65.5, 0.0, 0.0), "no-reflection": (17.5, 16.5, 1.0, 0.9),
                         "no-dpo": (35.3, 34.9, 2.9, 2.9)}


def test_method_and_split_from_adapt_trains_output_folder(tmp_path):
    """`adapt train` writes OUT/train.json, OUT/settings.json and the model OUT/merged: the method is
    train.json's, the split the training data's (its pairs carry it)."""
    data, out = tmp_path / "data", tmp_path / "nr"
    data.mkdir()
    (out / "merged").mkdir(parents=True)
    (data / "pairs.jsonl").write_text(json.dumps({"split": 2, "persona": "juan"}) + "\n")
    (out / "train.json").write_text(json.dumps({"method": "no-reflection", "rows": 10}))
    (out / "settings.json").write_text(json.dumps({"data": str(data), "model": "base"}))
    rec = Resolver().resolve(_rec("planner", agent_config={"model": str(out / "merged")}), None)
    assert (rec.agent, rec.split) == ("no-reflection", 2)
    (out / "train.json").write_text(json.dumps({"method": "sft", "split": "1"}))
    rec = Resolver().resolve(_rec("planner", agent_config={"model": str(out / "merged")}), None)
    assert (rec.agent, rec.split) == ("no-dpo", 1)


def test_a_base_student_counts_on_its_split_and_stays_the_baseline(tmp_path):
    """A base student's student.json (`adapt model curve`, the shipped `--model student`) gives its split:
    its planner rows are the baseline, in the unseen column only for its split's unseen personas."""
    base = tmp_path / "base"
    base.mkdir()
    (base / "student.json").write_text(json.dumps({"split": "0", "scene_seeds": [100, 101], "teacher": "oracle"}))
    unseen = {0: ("leila", "lisa", "mark", "samantha")}
    recs = [Resolver().resolve(_rec("planner", persona=p, agent_config={"model": str(base)}), None)
            for p in ("leila", "juan")]
    assert [(r.agent, r.split) for r in recs] == [("planner", 0), ("planner", 0)]
    from adaptbench.harness.evaluate import split_of

    assert [split_of(r, unseen) for r in recs] == [["unseen"], ["seen"]]


def test_tables_show_missing_rows_never_zero_and_the_paper_beside():
    recs = [_rec("never-ask-llm", rate=0.25, questions=0), _rec("never-ask", rate=0.5, questions=0),
            _rec("oracle", rate=1.0, questions=0), _rec("mine", rate=0.75)]
    rows = table(recs)
    sections = dict(pt.sections(rows))
    filled = {prow.id: (row["agent"] if row else None) for prow, row in sections["Table 1"]}
    assert filled == {"never-ask": "never-ask-llm", "baseline": None, "react": None, "star-gate": None,
                      "reflection-dpo": None, "always-ask": None, "teacher": "oracle"}
    assert [row["agent"] for _, row in sections["Other methods"]] == ["never-ask", "mine"]  # the scripted one too
    text = pt.render_text(rows, paper=True)
    baseline = next(line for line in text.splitlines() if line.startswith("baseline "))
    assert "missing" in baseline and "0.0%" not in baseline.split("missing")[1].split("34.7%")[0]
    assert "34.7% ± 0.8%" in baseline and "2.3 ± 0.0 / 2.3 ± 0.1" in baseline
    assert "Paper (seen)" in text and "Paper (seen)" not in pt.render_text(rows)
    assert "Table 2" in text and "no-reflection" in text and "17.5% ± 0.7%" in text
    lines = list(csv.reader(pt.render_csv(rows).splitlines()))
    head = lines[0]
    miss = dict(zip(head, next(r for r in lines if r[1] == "baseline"), strict=True))
    assert miss["agent"] == "" and miss["episodes"] == "0" and miss["rate_seen"] == "" and miss["paper_rate_seen"] == "34.7"
    ours = dict(zip(head, next(r for r in lines if r[1] == "never-ask"), strict=True))
    assert ours["agent"] == "never-ask-llm" and ours["rate_seen"] == "0.25" and ours["paper_rate_unseen"] == "28.6"
    assert any(line.startswith("missing (no records): baseline") for line in pt.notes(rows))


def test_each_trained_method_is_seen_or_unseen_by_its_split(domain):
    split, held_out = next(iter(domain.unseen.items()))
    seen_persona = next(p for p in domain.persona if p not in held_out)
    recs = [_rec("reflection-dpo", persona=held_out[0], rate=0.2, split=split, questions=4),
            _rec("reflection-dpo", persona=seen_persona, rate=0.6, split=split, questions=2),
            _rec("reflection-dpo", persona=seen_persona, rate=0.8, seed=1, split=split, questions=2)]
    row = table(recs, domain.unseen)[0]
    assert row["rate_unseen"] == (0.2, 0.0) and row["rate_seen"][0] == pytest.approx(0.7)
    assert row["rate_seen"][1] == pytest.approx(0.1) and row["questions_unseen"] == (4, 0.0)
    assert row["splits"] == (split,)
    nosplit = table([_rec("no-dpo", rate=0.5)])
    assert any("no-dpo: trained, but no record says on which split" in line for line in pt.notes(nosplit))


def test_mixed_models_within_a_method_are_named():
    recs = [_rec("planner", agent_config={"agent": "planner", "model": "base"}),
            _rec("planner", seed=1, agent_config={"agent": "planner", "model": "forgot-provenance"})]
    (line,) = mixed_models(recs)
    assert line.startswith("planner mixes 2 agents/models") and "forgot-provenance" in line


ANA = ["Look for eggs", "Look for pan", "Look for plate", "Look for oat milk", "Look for olive oil", "Look for butter",
       'Ask "How do you like your eggs?"', "Move pan_0 to stove_0", "Pour olive_oil from oil_bottle_0 to pan_0",
       "Move egg_0 to pan_0", "Move egg_1 to pan_0", "Turn on stove_0",
       "scramble items in pan_0 to get scrambled_eggs", "Move scrambled_eggs from pan_0 to plate_0",
       "Move plate_0 to table_0", "Declare Done"]


class _Script(Policy):
    name = "script"

    def __init__(self, actions):
        self.actions = list(actions)

    def act(self, view):
        return Decision(self.actions.pop(0))


def _known_episode(small) -> EpisodeRecord:
    """Ana's scrambled eggs without the oat milk (tests/spec_small): scrambled and no-butter satisfied, oat
    milk violated; the dish reaches the table at step 15 of 16."""
    env = make_env(small, "ana", "eggs", None, full_scene=True)
    ep = run_episode(_Script(ANA), env)
    return EpisodeRecord.from_dict(record(ep, Job("script", "ana", "eggs", 0), {"agent": "script"}, small.spec_hash))


def test_temporal_curve_of_a_known_episode():
    small = load_domain(SMALL)
    rec = _known_episode(small)
    assert (rec.satisfied, rec.violated, len(rec.steps)) == (2, 1, 16)
    curve = replay_curve(rec, small)
    assert curve.counts == (0,) * 15 + (2, 2)  # nothing counts until the dish is served (step 15)
    assert (curve.satisfied, curve.applicable) == (2, 3)
    assert curve.at(0.9) == 0.0 and curve.at(15 / 16) == pytest.approx(2 / 3) and curve.at(1.0) == pytest.approx(2 / 3)
    assert curve.at(1.0, normalised=True) == 1.0
    other = Curve((0, 1, 1, 2), 2, 4)  # half way: 1 of 4 applicable, 1 of the 2 finally satisfied
    pts = {x: (m, n) for x, m, _, n in mean_curve([curve, other], grid=(0.0, 0.5, 1.0))}
    assert pts[0.5] == (pytest.approx((0 + 0.25) / 2), 2) and pts[1.0][0] == pytest.approx((2 / 3 + 0.5) / 2)
    assert mean_curve([curve, other], normalised=True, grid=(0.5,))[0][1] == pytest.approx(0.25)


def test_a_record_the_replay_does_not_reproduce_is_left_out_and_counted():
    small = load_domain(SMALL)
    rec = _known_episode(small)
    steps = list(rec.steps)
    steps[14] = type(steps[14])("Move plate_0 to table_0", False, "failed")  # the record says serving failed
    tampered = EpisodeRecord(**{**rec.__dict__, "steps": tuple(steps)})
    out = replay_all([rec, tampered, EpisodeRecord(**{**rec.__dict__, "spec_hash": "other"})], small)
    assert len(out.curves["script"]) == 1
    assert out.skipped == {"replay differs from the record": 1, "spec differs from --spec": 1}


def _as_student(src, dst, model: str) -> None:
    """The records of `src` as if a planner on the model directory `model` had written them."""
    recs = [json.loads(line) for line in src.read_text().splitlines()]
    dst.write_text("".join(json.dumps({**r, "agent": "planner", "agent_config": {"agent": "planner", "model": model}})
                           + "\n" for r in recs))


def test_cli_both_tables_and_both_figures_from_scripted_rollouts(tmp_path, domain, capsys):
    """Scripted rollouts fill never-ask, always-ask and teacher (oracle); never-ask's records, relabelled as
    a planner on a trained model's directory, stand in for Reflection-DPO (its training.json) and for the
    no-DPO ablation (--method): every other row is missing."""
    split, held_out = next(iter(domain.unseen.items()))
    personas = f"{held_out[0]},{next(p for p in domain.persona if p not in held_out)}"
    runs, never = tmp_path / "scripted.jsonl", tmp_path / "never.jsonl"
    grid = ["--personas", personas, "--tasks", "toast_coffee", "--seeds", "0-1", "--quiet", "--spec", str(SPEC)]
    assert main(["rollout", "--agent", "oracle,never-ask,always-ask", "--out", str(runs), *grid]) == 0
    assert main(["rollout", "--agent", "never-ask", "--out", str(never), *grid]) == 0
    (tmp_path / "dpo").mkdir()
    (tmp_path / "dpo" / "training.json").write_text(json.dumps({"method": "dpo", "split": split}))
    _as_student(never, tmp_path / "dpo.jsonl", "dpo")  # relative to the results file's folder
    _as_student(never, tmp_path / "sft.jsonl", str(tmp_path / "sft"))  # no provenance: --method says
    out = tmp_path / "out"
    out.mkdir()
    args = ["eval", str(runs), str(tmp_path / "dpo.jsonl"), "--method", f"sft@{split}={tmp_path / 'sft.jsonl'}",
            "--paper", "--plot-temporal", str(out / "temporal.png"), "--plot-questions", str(out / "questions.png"),
            "--markdown", str(out / "tables.md"), "--csv", str(out / "tables.csv")]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "Table 1" in text and "Table 2" in text and "pass^2" in text and "Other methods" not in text
    rows = {}
    for line in text.splitlines():
        if line.split():
            rows.setdefault(line.split()[0], line)
    assert "oracle" in rows["teacher"] and "100.0% ± 0.0%" in rows["teacher"] and "65.5% ± 1.1%" in rows["teacher"]
    assert "always-ask" in rows["always-ask"] and "missing" in rows["react"] and "missing" in rows["no-reflection"]
    assert rows["reflection-dpo"].split()[1] == "reflection-dpo" and rows["no-dpo"].split()[1] == "no-dpo"
    for name in ("temporal.png", "questions.png"):
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    md = (out / "tables.md").read_text()
    assert md.startswith("**Table 1**") and "**Table 2**" in md and "| Paper (seen) |" in md
    table_csv = list(csv.DictReader((out / "tables.csv").read_text().splitlines()))
    dpo_rows = [r for r in table_csv if r["paper_row"] == "reflection-dpo"]
    assert len(dpo_rows) == 2 and all(r["episodes"] == "4" for r in dpo_rows)  # in Table 1 and in Table 2
    never_row = next(r for r in table_csv if r["paper_row"] == "never-ask")
    for r in dpo_rows:  # each persona counts once, seen or unseen by the split: the held-out one is unseen
        assert r["rate_seen"] and r["rate_unseen"] and r["questions_seen"] == "0"
    assert float(never_row["rate_seen"]) == pytest.approx((float(dpo_rows[0]["rate_seen"])
                                                           + float(dpo_rows[0]["rate_unseen"])) / 2, rel=1e-4)


def test_cli_eval_method_errors(tmp_path, capsys):
    f = tmp_path / "r.jsonl"
    f.write_text(json.dumps({"agent": "x", "persona": "juan", "task": "eggs", "seed": 0, "satisfaction_rate": 1.0,
                             "questions": 0}) + "\n")
    assert main(["eval", "--method", "nofile"]) == 2
    assert "is not NAME=FILE" in capsys.readouterr().err
    assert main(["eval"]) == 2
    assert "give results files" in capsys.readouterr().err
    assert main(["eval", "--method", f"dpo@7={f}"]) == 1
    assert "split 7" in capsys.readouterr().err
    other = tmp_path / "other.jsonl"  # a record of another spec cannot be replayed: said, exit 1, no figure
    other.write_text(json.dumps({"agent": "x", "persona": "juan", "task": "eggs", "seed": 0, "spec_hash": "other",
                                 "satisfaction_rate": 1.0, "questions": 0, "satisfied": 1, "violated": 0,
                                 "preferences": [{"id": "p", "verdict": "satisfied"}]}) + "\n")
    assert main(["eval", str(other), "--plot-temporal", str(tmp_path / "t.png")]) == 1
    err = capsys.readouterr().err
    assert "1 episode(s) left out of the temporal figure: 1 spec differs from --spec" in err
    assert "no episode could be replayed" in err and not (tmp_path / "t.png").exists()
    with pytest.raises(SystemExit) as exc:
        main(["eval", str(f), "--pass-k", "0"])
    assert exc.value.code == 2 and "each k must be at least 1" in capsys.readouterr().err
