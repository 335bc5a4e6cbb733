"""pass^k (tau-bench's estimator) over scene seeds and question precision (`adapt eval`), and the question targets recorded
with each question step (record version 2); older records still read, precision n/a."""

from __future__ import annotations

import json

from adaptbench.agents.users import OfflineUser, question_targets
from adaptbench.cli import main
from adaptbench.harness.episode import run_episode
from adaptbench.harness.evaluate import render_csv, render_text, table
from adaptbench.harness.metrics import fully_satisfied, judge_questions, pass_hat_k, pass_k, precision
from adaptbench.harness.policy import Decision, Policy
from adaptbench.harness.record import RECORD_VERSION, EpisodeRecord
from adaptbench.runtime.env import Env

from ..conftest import SPEC


def _rec(persona, task, seed, rate, violated=0, steps=(), prefs=(), version=RECORD_VERSION, agent="x"):
    return EpisodeRecord.from_dict({"version": version, "agent": agent, "persona": persona, "task": task,
                                    "seed": seed, "satisfaction_rate": rate, "questions": len(steps),
                                    "violated": violated, "steps": list(steps), "preferences": list(prefs)})


def test_pass_k_is_taubenchs_estimator_over_persona_task_pairs():
    """pass^k = mean over (persona, task) of C(c, k) / C(n, k); episodes with nothing applicable are not
    counted, and a pair with none is left out."""
    recs = [_rec("a", "eggs", 0, 1.0), _rec("a", "eggs", 1, 1.0), _rec("a", "eggs", 2, 1.0),  # n=3, c=3
            _rec("b", "eggs", 0, 1.0), _rec("b", "eggs", 1, 0.5, 1), _rec("b", "eggs", 2, 1.0),  # n=3, c=2
            _rec("a", "cereal", 0, None), _rec("a", "cereal", 1, None), _rec("a", "cereal", 2, None)]  # left out
    pk = pass_k(recs, (1, 2, 3, 4))
    assert pk.rate(1) == (1 + 2 / 3) / 2  # the mean success rate
    assert pk.rate(2) == (1 + 1 / 3) / 2  # C(2,2)/C(3,2) = 1/3
    assert pk.rate(3) == 0.5 and pk.rate(4) is None  # no pair has 4 episodes
    assert pk.pairs == (2, 2, 2, 0) and pk.left_out == 1
    # a pair with fewer episodes counts only for the k it has; an episode with nothing applicable is not one
    more = recs + [_rec("c", "eggs", 0, 1.0), _rec("c", "eggs", 1, 0.0, 2), _rec("c", "eggs", 2, None)]
    pk = pass_k(more, (1, 2, 3))
    assert pk.rate(1) == (1 + 2 / 3 + 1 / 2) / 3 and pk.rate(2) == (1 + 1 / 3 + 0) / 3
    assert pk.rate(3) == 0.5 and pk.pairs == (3, 3, 2)
    assert pass_hat_k(4, 2, 2) == 1 / 6 and pass_hat_k(4, 1, 2) == 0.0
    assert pass_k([]).rate(1) is None


def test_success_needs_every_applicable_preference_satisfied():
    assert fully_satisfied(_rec("a", "eggs", 0, 1.0))
    assert not fully_satisfied(_rec("a", "eggs", 0, 0.8, 1))
    assert not fully_satisfied(_rec("a", "eggs", 0, None))  # nothing applied: neither success nor failure


def _ask(question, targets=None):
    step = {"action": f'Ask "{question}"', "ok": True, "observation": "", "reply": "r"}
    return step if targets is None else {**step, "targets": targets}


def test_precision_counts_questions_that_reveal_a_new_applicable_preference():
    prefs = [{"id": "p1", "verdict": "satisfied"}, {"id": "p2", "verdict": "inapplicable"},
             {"id": "p3", "verdict": "violated"}]
    steps = [_ask("q1", ["p1"]),  # precise: p1 applies and is new
             _ask("q2", ["p2"]),  # off: p2 does not apply to the task
             _ask("q3", []),  # off: no preference (e.g. where is the milk?)
             _ask("q4", ["p1"]),  # repeat: p1 is known
             _ask("q5", ["p1", "p3"]),  # precise: p3 is new
             {"action": "Search fridge_0", "ok": True, "observation": ""},
             {"action": 'Ask "q6"', "ok": False, "observation": "", "targets": ["p3"]}]  # failed: not a question
    rec = _rec("a", "eggs", 0, 0.5, steps=steps, prefs=prefs)
    assert judge_questions(rec) == ["precise", "off", "off", "repeat", "precise"]
    pr = precision([rec])
    assert (pr.precise, pr.judged, pr.repeat, pr.off, pr.unjudged) == (2, 5, 1, 2, 0) and pr.rate == 0.4
    old = _rec("a", "eggs", 0, 1.0, steps=[_ask("q1")], prefs=prefs, version=1)
    assert precision([old]).rate is None and precision([old]).unjudged == 1


def test_table_renders_both_metrics_and_na():
    prefs = [{"id": "p1", "verdict": "satisfied"}]
    recs = [_rec("a", "eggs", s, 1.0, steps=[_ask("q", ["p1"])], prefs=prefs) for s in (0, 1)]
    recs.append(_rec("a", "eggs", 0, 1.0, steps=[_ask("q")], prefs=prefs, version=1, agent="old"))
    rows = table(recs)
    text = render_text(rows)
    assert "pass^1" in text and "pass^2" not in text and "Question precision" in text  # agent old has 1 seed
    assert "100.0% (2/2)" in text and "n/a" in text
    csv_lines = render_csv(rows).splitlines()
    assert csv_lines[0].endswith("pass_1,pass_k_pairs,pass_k_left_out,question_precision,questions_precise,"
                                 "questions_judged,questions_repeat,questions_off")
    x_row = next(line for line in csv_lines if line.startswith("x,"))
    assert x_row.split(",")[-8:] == ["1", "1", "0", "1", "2", "2", "0", "0"]


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


def test_one_k_for_every_row_the_most_seeds_every_pair_has():
    """Method a ran seeds 0-2, method b seeds 0-1: both rows show pass^1 and pass^2 (a's from its 3 seeds)."""
    recs = [_rec("p", "eggs", s, 1.0 if s < 2 else 0.5, violated=int(s == 2), agent="a") for s in (0, 1, 2)]
    recs += [_rec("p", "eggs", s, 1.0, agent="b") for s in (0, 1)]
    rows = {r["agent"]: r for r in table(recs)}
    assert rows["a"]["pass_k"].ks == rows["b"]["pass_k"].ks == (1, 2)
    assert rows["a"]["pass_k"].rate(2) == 1 / 3 and rows["b"]["pass_k"].rate(2) == 1.0
    assert table(recs, ks=(3,))[1]["pass_k"].rate(3) is None  # b has no pair with 3 seeds
    from adaptbench.harness.evaluate import notes

    assert any("k=2 is the most seeds every (method, persona, task) pair has" in line for line in
               notes(list(rows.values())))
    assert "33.3%" in render_text(list(rows.values()))
