"""pass^k over scene seeds and question precision (`adapt eval`), and the question targets recorded
with each question step (record version 2); older records still read, precision n/a."""

from __future__ import annotations

import json

from adaptbench.agents.users import OfflineUser, question_targets
from adaptbench.cli import main
from adaptbench.harness.episode import run_episode
from adaptbench.harness.evaluate import render_csv, render_text, table
from adaptbench.harness.metrics import pass_k, precision
from adaptbench.harness.policy import Decision, Policy
from adaptbench.harness.record import RECORD_VERSION, EpisodeRecord
from adaptbench.runtime.env import Env

from ..conftest import SPEC


def _rec(persona, task, seed, rate, violated=0, steps=(), prefs=(), version=RECORD_VERSION, agent="x"):
    return EpisodeRecord.from_dict({"version": version, "agent": agent, "persona": persona, "task": task,
                                    "seed": seed, "satisfaction_rate": rate, "questions": len(steps),
                                    "violated": violated, "steps": list(steps), "preferences": list(prefs)})


def test_pass_k_needs_every_seed_and_leaves_out_pairs_without_preferences():
    recs = [_rec("a", "eggs", 0, 1.0), _rec("a", "eggs", 1, 1.0), _rec("a", "eggs", 2, 1.0),  # passes
            _rec("b", "eggs", 0, 1.0), _rec("b", "eggs", 1, 0.5, 1), _rec("b", "eggs", 2, 1.0),  # fails one seed
            _rec("a", "cereal", 0, None), _rec("a", "cereal", 1, None), _rec("a", "cereal", 2, None)]  # left out
    pk = pass_k(recs)
    assert (pk.passed, pk.pairs, pk.k, pk.left_out) == (1, 2, (3, 3), 1)
    assert pk.rate == 0.5 and pk.k_text == "3"
    assert pass_k(recs[:5]).k_text == "2-3"
    assert pass_k([]).rate is None


def _ask(question, targets=None):
    step = {"action": f'Ask "{question}"', "ok": True, "observation": "", "reply": "r"}
    return step if targets is None else {**step, "targets": targets}


def test_precision_counts_questions_naming_an_applicable_preference():
    prefs = [{"id": "p1", "verdict": "satisfied"}, {"id": "p2", "verdict": "inapplicable"}]
    rec = _rec("a", "eggs", 0, 1.0, steps=[_ask("q1", ["p1"]), _ask("q2", ["p2"]), _ask("q3", []),
                                           {"action": "Search fridge_0", "ok": True, "observation": ""}],
               prefs=prefs)
    pr = precision([rec])
    assert (pr.precise, pr.judged, pr.unjudged) == (1, 3, 0)
    old = _rec("a", "eggs", 0, 1.0, steps=[_ask("q1")], prefs=prefs, version=1)
    assert precision([old]).rate is None and precision([old]).unjudged == 1


def test_table_renders_both_metrics_and_na():
    prefs = [{"id": "p1", "verdict": "satisfied"}]
    recs = [_rec("a", "eggs", s, 1.0, steps=[_ask("q", ["p1"])], prefs=prefs) for s in (0, 1)]
    recs.append(_rec("a", "eggs", 0, 1.0, steps=[_ask("q")], prefs=prefs, version=1, agent="old"))
    rows = table(recs)
    text = render_text(rows)
    assert "pass^k" in text and "Question precision" in text
    assert "100.0% (1/1, k=1)" in text and "100.0% (2/2)" in text and "n/a" in text  # one k: agent old has 1 seed
    csv_lines = render_csv(rows).splitlines()
    assert csv_lines[0].endswith("pass_k_left_out,question_precision,questions_precise,questions_judged")
    x_row = next(line for line in csv_lines if line.startswith("x,"))
    assert x_row.split(",")[-9:] == ["1", "1", "1", "1", "1", "0", "1", "2", "2"]  # k_min = k_max = 1: one k for all rows


class _Asker(Policy):
    name = "asker"

    def __init__(self, questions):
        self.questions = list(questions)

    def act(self, view):
        return Decision(f'Ask "{self.questions.pop(0)}"' if self.questions else "Declare Done")


def test_question_steps_record_the_offline_users_targets(domain):
    persona = domain.personas[0]
    pref = persona.preferences[0]
    question = f"How do you like the {pref.topics[0]}?" if pref.topics else pref.text
    user = OfflineUser(domain, persona, domain.task["eggs"])
    env = Env(domain, "eggs", persona.id, 0, user=user)
    ep = run_episode(_Asker([question, "Where is the egg?"]), env)
    asked, where, done = ep.steps
    assert asked.targets == user.targets(question) == question_targets(env, question)
    assert pref.id in asked.targets
    assert where.targets == () and done.targets is None
    back = EpisodeRecord.from_dict(json.loads(json.dumps({"agent": "asker", "persona": persona.id, "task": "eggs",
                                                          "seed": 0, "satisfaction_rate": None, "questions": 2,
                                                          "steps": [s.to_dict() for s in ep.steps]})))
    assert back.steps[0].targets == asked.targets and back.steps[2].targets is None


def test_cli_eval_shows_metrics_and_reads_old_records(tmp_path, domain, capsys):
    persona = domain.personas[0].id
    out = tmp_path / "r.jsonl"
    assert main(["rollout", "--agent", "always-ask", "--personas", persona, "--tasks", "eggs",
                 "--seeds", "0-1", "--out", str(out), "--quiet", "--spec", str(SPEC)]) == 0
    recs = [json.loads(line) for line in out.read_text().splitlines()]
    assert all(r["version"] == RECORD_VERSION for r in recs)
    assert any("targets" in s for r in recs for s in r["steps"])
    assert main(["eval", str(out)]) == 0
    text = capsys.readouterr().out
    assert "k=2" in text
    old = tmp_path / "old.jsonl"
    stripped = [{**r, "version": 1, "steps": [{k: v for k, v in s.items() if k != "targets"} for s in r["steps"]]}
                for r in recs]
    old.write_text("".join(json.dumps(r) + "\n" for r in stripped))
    assert main(["eval", str(old)]) == 0
    text = capsys.readouterr().out
    assert "n/a" in text and "not judged for question precision" in text


def test_any_users_questions_are_judged_by_the_offline_matcher(domain):
    persona = domain.personas[0]
    pref = persona.preferences[0]
    question = f"How do you like the {pref.topics[0]}?" if pref.topics else pref.text
    env = Env(domain, "eggs", persona.id, 0, user=lambda q, dialogue: "Whatever you like.")  # e.g. an LLM user
    asked, _done = run_episode(_Asker([question]), env).steps
    assert asked.reply == "Whatever you like." and pref.id in asked.targets


def test_one_k_for_every_row_the_smallest_number_of_seeds_every_pair_has():
    """Agent a ran seeds 0-2, agent b seeds 0-1: both rows use k=2 (a's seed 2 is not counted), and the
    table says which k."""
    recs = [_rec("p", "eggs", s, 1.0 if s < 2 else 0.5, violated=int(s == 2), agent="a") for s in (0, 1, 2)]
    recs += [_rec("p", "eggs", s, 1.0, agent="b") for s in (0, 1)]
    rows = {r["agent"]: r for r in table(recs)}
    assert rows["a"]["pass_k"].k_text == rows["b"]["pass_k"].k_text == "2"
    assert rows["a"]["pass_k"].passed == 1  # failed only in seed 2, which k=2 does not count
    from adaptbench.harness.evaluate import notes

    assert any(line.startswith("pass^k: k=2 for every row, the smallest number of scene seeds") for line in
               notes(list(rows.values())))
    assert "100.0% (1/1, k=2)" in render_text(list(rows.values()))
