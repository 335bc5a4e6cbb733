"""Reflection-DPO's dataset (`adapt train data`, adaptbench.training): the decision rule, Δ through the batched
scoring path against a direct forward pass, left truncation of long prompts, resume after a kill, provenance."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from adaptbench.training.dataset import FIELDS, PairStore, summarise
from adaptbench.training.decide import decide

from .conftest import SKIP_MODELS, play


@pytest.mark.parametrize(("pt", "pta", "ps", "kind", "reason"), [
    (0.6, 0.6, 0.4, "teacher", None),        # Δt < 0: the student already leans to a^t
    (0.1, 0.5, 0.6, "question", None),       # Δt = 0.5 >= 0, Δq = 0.4 > ε1
    (0.1, 0.25, 0.5, "teacher", None),       # Δq = 0.15 <= ε1, Δt = 0.4 < ε2
    (0.1, 0.2, 0.9, "skipped", "no_gain"),   # Δq = 0.1, Δt = 0.8 >= ε2
    (0.25, 0.375, 0.75, "skipped", "no_gain"),  # Δt = 0.5 exactly is not < ε2
])
def test_decision_rule(pt, pta, ps, kind, reason):
    d = decide(pt, pta, ps)
    assert (d.kind, d.skip_reason) == (kind, reason)
    assert d.delta_q == pytest.approx(pta - pt) and d.delta_t == pytest.approx(ps - pt)


def test_decision_rule_thresholds_are_options():
    assert decide(0.1, 0.25, 0.9, eps1=0.1).kind == "question"
    assert decide(0.1, 0.1, 0.9, eps2=0.9).kind == "teacher"


def _direct(model, tok, prompt: str, action: str) -> float:
    import torch

    p = tok(prompt, add_special_tokens=False)["input_ids"]
    from adaptbench.llm.chat import end_token

    a = action if isinstance(action, list) else tok(action, add_special_tokens=False)["input_ids"] + [end_token(tok)]
    with torch.no_grad():
        logits = model(input_ids=torch.tensor([p + a])).logits[0].float()
    logp = torch.log_softmax(logits, -1)
    probs = [logp[len(p) - 1 + j, t].exp().item() for j, t in enumerate(a)]
    return sum(probs) / len(probs)


@SKIP_MODELS
def test_delta_batched_equals_direct_forward(backend, domain):
    from transformers import AutoModelForCausalLM

    from adaptbench.llm.chat import render
    from adaptbench.training.relabel import answered_prompt, student_policy
    from adaptbench.training.score import step_probabilities

    student = student_policy(backend, domain)
    ep, _ = play(domain)
    view = ep.view()
    student.start(ep.id, ep.env)
    d = student.act_batch([view])[0]
    x = render(backend.tokenizer, d.prompt)
    q = 'Ask "How do you like your eggs?"'
    xq = render(backend.tokenizer, answered_prompt(student, d.prompt, view, q, "Scrambled, please."))
    teacher, own = "Move egg_0 to pan_0", "Look for butter"
    probs = step_probabilities(backend, x, xq, teacher, own)
    model = AutoModelForCausalLM.from_pretrained(backend.config()["model"], dtype="float32").eval()
    tok = backend.tokenizer
    assert probs.p_teacher == pytest.approx(_direct(model, tok, x, teacher), abs=1e-5)
    assert probs.p_student == pytest.approx(_direct(model, tok, x, own), abs=1e-5)
    assert probs.p_teacher_given_answer == pytest.approx(_direct(model, tok, xq, teacher), abs=1e-5)
    generated = d.stats["token_ids"]  # on-policy: the student's own action is scored on the ids it generated
    on_policy = step_probabilities(backend, x, xq, teacher, d.action, generated)
    assert on_policy.p_student == pytest.approx(_direct(model, tok, x, generated), abs=1e-5)
    assert on_policy.p_teacher == probs.p_teacher


@SKIP_MODELS
def test_long_prompt_loses_old_observations_first_never_a_question_or_its_answer(backend, domain):
    from adaptbench.llm.chat import count, render
    from adaptbench.training.relabel import student_policy
    from adaptbench.training.rows import ELIDED, fit_prompt

    student = student_policy(backend, domain, budget=None)
    ep, _ = play(domain, steps=("Look for eggs", 'Ask "How do you like your eggs?"', "Open fridge_0", "Look for butter",
                                "Look for pan", "Look for milk", "Look for salt"))
    student.start(ep.id, ep.env)
    prompt = student.act_batch([ep.view()])[0].prompt
    tok = backend.tokenizer
    full = count(tok, render(tok, prompt))
    question = next(m for m in prompt.messages if m["content"] == 'Action: Ask "How do you like your eggs?"')
    answer = prompt.messages[prompt.messages.index(question) + 1]
    assert "scrambled" in answer["content"].lower()
    fitted = fit_prompt(tok, prompt, 10, full - 20)
    assert fitted.truncated and fitted.tokens <= full - 30 and fitted.qa_kept == fitted.qa_total == 1
    assert fitted.tokens == count(tok, render(tok, fitted.prompt))
    assert question in fitted.prompt.messages and answer in fitted.prompt.messages  # the answer kept whole
    assert fitted.prompt.messages[:2] == prompt.messages[:2] and fitted.prompt.messages[-1] == prompt.messages[-1]
    assert any(m["content"] == ELIDED for m in fitted.prompt.messages)  # observations go first
    tight = fit_prompt(tok, prompt, 10, 50)  # nothing but the task, questions and answers: still too long
    assert tight.over > 0 and tight.qa_kept == 1 and question in tight.prompt.messages
    same = fit_prompt(tok, prompt, 10, full + 10)
    assert not same.truncated and same.tokens == full and same.prompt.messages == prompt.messages


@SKIP_MODELS
def test_a_long_episodes_rows_keep_every_answer_and_are_scored_on_their_own_prompt(backend, domain, tmp_path):
    from adaptbench.llm.chat import count, render
    from adaptbench.llm.prompts import Prompt
    from adaptbench.training.data import Builder, DataSettings, opening_tokens
    from adaptbench.training.relabel import student_policy
    from adaptbench.training.score import step_probabilities

    base = DataSettings(1, ("juan",), ("eggs",), (100,), questions="topics", max_length=None, width=1, max_steps=10)
    opening = opening_tokens(domain, student_policy(backend, domain), base)
    from dataclasses import replace

    settings = replace(base, max_length=opening + 320)  # room for the question, its answer and a long action, not for the rest
    store = PairStore(tmp_path)
    Builder(domain, _asking_student(backend, domain), settings, store, "tiny").run()
    rows = store.rows
    assert len(rows) == 10 and any(r["truncated"] for r in rows)
    tok = backend.tokenizer
    for r in rows[1:]:
        assert r["qa_total"] == r["qa_kept"] == 1
        assert any(m["content"] == 'Action: Ask "How do you like your eggs?"' for m in r["prompt"])
        x = render(tok, Prompt(tuple(r["prompt"]), "Action: "))
        assert r["prompt_tokens"] == count(tok, x)
        if r["p_teacher"] is not None:  # scored on exactly the prompt it trains on
            again = step_probabilities(backend, x, x, r["teacher_action"], r["student_action"])
            assert again.p_teacher == pytest.approx(r["p_teacher"], abs=1e-6)
    assert summarise(rows)["rows_lost_qa"] == 0 and summarise(rows)["scene_seeds"] == [100]


@SKIP_MODELS
def test_no_skip_after_failures_unless_asked(backend, domain, tmp_path):
    from dataclasses import replace

    from adaptbench.training.data import Builder, DataSettings
    from adaptbench.training.relabel import student_policy

    student = student_policy(backend, domain)
    own = student.act_batch
    student.act_batch = lambda views: [replace(d, action="Open unicorn_0") for d in own(views)]  # fails every step
    settings = DataSettings(1, ("juan",), ("eggs",), (100,), questions="topics", max_length=None, width=1, max_steps=5)
    store = PairStore(tmp_path / "off")
    Builder(domain, student, settings, store, "tiny").run()
    assert len(store.rows) == 5 and not any((r["skip_reason"] or "").startswith("after_") for r in store.rows)
    on = PairStore(tmp_path / "on")
    Builder(domain, student, replace(settings, skip_after_failures=2), on, "tiny").run()
    assert [r["skip_reason"] for r in on.rows][2:] == ["after_2_failures"] * 3


@SKIP_MODELS
@pytest.mark.parametrize(("extra", "says"), [
    (("--seeds", "2-5"), "--seeds 2-3 meets the evaluation scene seeds 0-3"),
    (("--max-length", "300"), "cannot hold a row's opening prompt"),
])
def test_train_data_refuses_evaluation_seeds_and_a_length_that_cannot_hold_the_task(tiny, tmp_path, extra, says):
    cmd = [sys.executable, "-m", "adaptbench.cli", "train", "data", "--student", str(tiny), "--out",
           str(tmp_path / "d"), "--personas", "ron", "--tasks", "eggs", "--split", "1", *extra]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    said = [x for x in done.stderr.splitlines() if x.startswith("adapt:")]
    assert done.returncode == 2 and len(said) == 1 and says in said[0], done.stderr
    assert "Traceback" not in done.stderr and not (tmp_path / "d" / "pairs.jsonl").exists()


@SKIP_MODELS
def test_train_data_records_the_students_question_set(tiny, tmp_path):
    cmd = [sys.executable, "-m", "adaptbench.cli", "train", "data", "--student", str(tiny), "--out", str(tmp_path / "d"),
           "--personas", "sarah", "--tasks", "eggs", "--split", "1", "--batch", "1", "--max-steps", "2",
           "--question-set", "bank"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "d" / "summary.json").read_text())
    assert summary["selection"]["question_set"] == "bank"


def test_training_commands_default_to_seeds_apart_from_evaluation():
    from adaptbench.cli.main import build_parser
    from adaptbench.harness.rollout import parse_seeds
    from adaptbench.harness.seeds import EVAL_SEEDS
    from adaptbench.training.data import DataSettings
    from adaptbench.training.student import StudentSettings

    parser = build_parser()
    data = parser.parse_args(["train", "data", "--student", "x", "--out", "y"])
    grpo = parser.parse_args(["train", "grpo", "--model", "x", "--out", "y"])
    seeds = {"train data": parse_seeds(data.seeds), "grpo": list(grpo.seeds),
             "DataSettings": list(DataSettings(None, (), ()).seeds),
             "student": [*StudentSettings().ask_seeds, *StudentSettings().oracle_seeds]}
    for name, used in seeds.items():
        assert used and not set(used) & set(EVAL_SEEDS), name
    assert set(grpo.eval_seeds) <= set(EVAL_SEEDS)


def _cmd(tiny, out):
    return [sys.executable, "-m", "adaptbench.cli", "train", "data", "--student", str(tiny), "--out", str(out),
            "--personas", "sarah,ron", "--tasks", "eggs", "--split", "1", "--batch", "1", "--max-steps", "12"]


@SKIP_MODELS
def test_resume_after_kill_and_provenance(tiny, tmp_path):
    out = tmp_path / "data"
    proc = subprocess.Popen(_cmd(tiny, out), stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    pairs = out / "pairs.jsonl"
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None and (not pairs.is_file() or len(pairs.read_text().splitlines()) < 5):
        time.sleep(0.2)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    first = len(pairs.read_text().splitlines())
    assert first >= 5 and not (out / "summary.json").exists()
    done = subprocess.run(_cmd(tiny, out), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    rows = [json.loads(x) for x in pairs.read_text().splitlines()]
    keys = [(r["persona"], r["task"], r["seed"], r["interaction"], r["step"]) for r in rows]
    assert len(keys) == len(set(keys)) and len(rows) > first
    assert {r["persona"] for r in rows} == {"sarah", "ron"}
    for r in rows:
        assert set(FIELDS) <= set(r)
        assert r["split"] == 1 and r["task"] == "eggs" and r["teacher"] == "oracle" and r["spec_hash"]
        assert r["rejected"][0]["role"] == "assistant" and r["prompt"][0]["role"] == "system"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["pairs"] == len(rows) and "steps:" in done.stdout
    # the default --max-length holds every prompt whole; the default seeds are training scenes
    assert not any(r["truncated"] or r["over_budget"] for r in rows) and summary["rows_lost_qa"] == 0
    assert summary["scene_seeds"] == [100] and summary["max_steps"] == 12 and {r["seed"] for r in rows} == {100}
    assert "0 lost a question or answer" in done.stdout
    _check_rejected_ids(tiny, rows, summary)
    before = pairs.read_bytes(), (out / "summary.json").read_bytes()
    again = subprocess.run(_cmd(tiny, out), capture_output=True, text=True, timeout=120)  # a finished build: done
    assert again.returncode == 0 and "already holds this build" in again.stderr and "steps:" in again.stdout
    assert (pairs.read_bytes(), (out / "summary.json").read_bytes()) == before


def _check_rejected_ids(tiny, rows, summary):
    """Every row keeps the student's generated ids for its rejected answer, laid out as a DPO trainer cuts
    a completion after the prompt's generation prompt, and the summary counts them and the score dtype."""
    from transformers import AutoTokenizer

    tok = AutoTokenizer.from_pretrained(tiny)
    for r in rows:
        ids = r["rejected_token_ids"]
        assert ids and isinstance(r["rejected_canonical"], bool)
        opening = tok.apply_chat_template(r["prompt"], tokenize=False, add_generation_prompt=True)
        turn = tok.apply_chat_template(r["prompt"] + r["rejected"], tokenize=False)[len(opening):]
        assert tok.decode(ids) == turn  # the same text, in the ids the student took
        assert r["rejected_canonical"] == (ids == tok(turn, add_special_tokens=False)["input_ids"])
    counts = summary["rejected_ids"]
    assert counts["canonical"] + counts["non_canonical"] == len(rows) and counts["unknown"] == 0
    scored = [r for r in rows if r["p_student"] is not None]
    assert all(r["score_dtype"] == "float32" for r in scored) and summary["score_dtypes"] == (["float32"] if scored else [])


def test_store_drops_torn_line_and_summarises(tmp_path):
    row = {f: None for f in FIELDS} | {"kind": "skipped", "skip_reason": "same_action", "persona": "juan",
                                       "task": "eggs", "seed": 0, "interaction": 1, "step": 0, "prompt_tokens": 9,
                                       "truncated": False}
    store = PairStore(tmp_path)
    store.append(row)
    with (tmp_path / "pairs.jsonl").open("a") as f:
        f.write('{"kind": "sk')  # killed mid-write
    again = PairStore(tmp_path)
    assert len(again.rows) == 1 and again.done(("juan", "eggs", 0, 1, 0))
    again.append(row | {"step": 1})
    s = summarise(again.rows)
    assert s["pairs"] == 2 and s["skip_reasons"] == {"same_action": 2} and s["dropped"] == 0


# ---------------------------------------------------------------- issue 15 item 1: two interactions, LLM teacher, workers
def test_prior_summary_keeps_what_the_user_answered_from_a_preference(domain):
    from adaptbench.training.prior import learnt, prior_summary

    ep, _ = play(domain, steps=("Look for eggs", 'Ask "How do you like your eggs?"', 'Ask "how do you like your eggs?"',
                                'Ask "Where are the eggs?"', "Open fridge_0"))
    pairs = learnt(ep.steps)
    assert [q for q, _, _ in pairs] == ["How do you like your eggs?"]  # asked twice: once; where-is: nothing learnt
    assert "scrambled_or_omelette" in pairs[0][2]
    text = prior_summary(ep)
    assert 'You asked "How do you like your eggs?"' in text and "scrambled or as an omelette" in text
    assert "Where are the eggs" not in text and "prepare eggs for breakfast" in text
    nothing, _ = play(domain, steps=("Look for eggs", 'Ask "Where are the eggs?"'))
    assert prior_summary(nothing) == ""


def _asking_student(backend, domain, question='Ask "How do you like your eggs?"'):
    """The real student, except that it asks `question` at the first step of every first interaction (the random
    tiny model never asks), its prompt kept."""
    from dataclasses import replace

    from adaptbench.training.relabel import student_policy

    student = student_policy(backend, domain)
    own = student.act_batch

    def act_batch(views):
        return [replace(d, action=question) if v.step == 0 and v.episode.endswith("/i1") else d
                for v, d in zip(views, own(views), strict=True)]
    student.act_batch = act_batch
    return student


@SKIP_MODELS
def test_second_interaction_prompt_carries_the_first_interactions_summary(backend, domain, tmp_path):
    from adaptbench.training.data import Builder, DataSettings

    settings = DataSettings(1, ("juan",), ("eggs",), (0,), interactions=2, questions="topics", max_length=None,
                            width=1, max_steps=3)
    store = PairStore(tmp_path)
    Builder(domain, _asking_student(backend, domain), settings, store, "tiny").run()
    by = {i: [r for r in store.rows if r["interaction"] == i] for i in (1, 2)}
    assert [r["step"] for r in by[1]] == [0, 1, 2] and [r["step"] for r in by[2]] == [0, 1, 2]
    for r in by[1]:
        assert r["prior"] == "" and "You have no prior information about the user." in r["prompt"][0]["content"]
    assert by[1][0]["student_action"] == 'Ask "How do you like your eggs?"'
    for r in by[2]:
        system = r["prompt"][0]["content"]
        assert r["prior"] and r["prior"] in system and "no prior information" not in system
        assert 'You asked "How do you like your eggs?"' in system and "scrambled or as an omelette" in system


@SKIP_MODELS
def test_llm_teacher_sees_the_preferences_and_the_unmet_ones_and_acts_under_the_grammar(backend, domain):
    from dataclasses import replace

    from adaptbench.training.relabel import LLMTeacher

    teacher = LLMTeacher(backend, domain, "tiny-dir")
    ep, _ = play(domain, steps=("Look for eggs", "Open fridge_0"))
    teacher.start(ep.id, ep.env)
    view = ep.view()
    (a_t,) = teacher.actions([view])
    assert teacher.policy.index.parser.parse(a_t) is not None  # a^t is an action of the grammar
    prompt, _, _ = teacher.policy._prepare(replace(view, episode=teacher._key(view.episode)))
    system, last = prompt.messages[0]["content"], prompt.messages[-1]["content"]
    prefs = [p.text for p in domain.persona["juan"].preferences]
    assert all(p in system for p in prefs)  # privileged: every preference of the persona
    assert "Preferences not yet met:" in last  # the verifier's unmet ones, reminded at this step
    assert teacher.name == "llm" and teacher.model == "tiny-dir"
    teacher.end(ep.id)


def _cmd2(tiny, out, *extra):
    return [sys.executable, "-m", "adaptbench.cli", "train", "data", "--student", str(tiny), "--out", str(out),
            "--personas", "sarah,ron,lisa,maya", "--tasks", "eggs", "--split", "1", "--batch", "1",
            "--max-steps", "3", "--interactions", "2", "--questions", "topics", *extra]


@SKIP_MODELS
def test_workers_llm_teacher_two_interactions_whole_process_resume(tiny, tmp_path):
    out = tmp_path / "data"
    cmd = _cmd2(tiny, out, "--teacher-model", str(tiny), "--workers", "2")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    pairs = out / "pairs.jsonl"
    deadline = time.time() + 180
    while time.time() < deadline and proc.poll() is None and (not pairs.is_file() or not pairs.read_text().strip()):
        time.sleep(0.2)
    os.kill(proc.pid, signal.SIGKILL)  # the parent: its workers die with it
    proc.wait()
    first = len(pairs.read_text().splitlines())
    assert first >= 1 and not (out / "summary.json").exists()
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    rows = [json.loads(x) for x in pairs.read_text().splitlines()]
    keys = [(r["persona"], r["task"], r["seed"], r["interaction"], r["step"]) for r in rows]
    assert len(keys) == len(set(keys)) == 4 * 2 * 3 > first  # 4 personas x 2 interactions x 3 steps, each once
    assert {(r["persona"], r["interaction"]) for r in rows} == {(p, i) for p in ("sarah", "ron", "lisa", "maya")
                                                                for i in (1, 2)}
    for r in rows:
        assert r["teacher"] == "llm" and r["teacher_model"] == str(tiny) and set(FIELDS) <= set(r)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["teacher"] == "llm" and summary["interactions"] == 2 and summary["pairs"] == 24


@SKIP_MODELS
def test_train_data_bad_teacher_model_and_gpu_workers_are_one_line(tiny, tmp_path):
    bad = subprocess.run(_cmd2(tiny, tmp_path / "d", "--teacher-model", str(tmp_path)), capture_output=True,
                         text=True, timeout=120)
    assert bad.returncode == 2 and bad.stderr.strip().splitlines()[-1].startswith("adapt: --teacher-model")
    assert "Traceback" not in bad.stderr
    gpu = subprocess.run(_cmd2(tiny, tmp_path / "d", "--workers", "2", "--device", "cuda"), capture_output=True,
                         text=True, timeout=120)
    assert gpu.returncode == 2 and "--workers above 1" in gpu.stderr and "Traceback" not in gpu.stderr


def test_same_action_compares_the_whole_parsed_action(domain):
    """Only the verb was compared: `Look for animal products` against the teacher's `Look for skillet` was
    skipped as the same action (SmolLM2's data was all skips)."""
    from adaptbench.runtime.index import runtime_index
    from adaptbench.training.data import same_action

    parser = runtime_index(domain).parser
    assert not same_action(parser, "Look for animal products", "Look for skillet")
    assert not same_action(parser, "Open fridge_0", "Open cabinet_0")
    assert same_action(parser, "Open fridge_0", "Open fridge_0 ")
    assert same_action(parser, "Look for skillet", "Look for skillet")


def _follow_build(backend, domain, out, follow: bool, monkeypatch, steps: int = 5):
    """A build where every scored step chooses its question unless ε1 rules it out (the rule's Δq forced
    to 1) and the student looks for bread at every step: with `follow` the rollout asks the chosen
    question instead."""
    from dataclasses import replace

    from adaptbench.training import data
    from adaptbench.training.data import Builder, DataSettings
    from adaptbench.training.decide import Decision
    from adaptbench.training.relabel import student_policy

    student = student_policy(backend, domain)
    own = student.act_batch
    student.act_batch = lambda views: [replace(d, action="Look for bread") for d in own(views)]
    settings = DataSettings(1, ("juan",), ("eggs",), (100,), questions="choices", max_length=None, width=1,
                            max_steps=steps, follow_questions=follow)
    store = PairStore(out)
    monkeypatch.setattr(data, "decide", lambda pt, pta, ps, eps1, eps2: Decision(
        "question" if eps1 < 1.0 else "teacher", None, 1.0, 0.0))
    Builder(domain, student, settings, store, "tiny").run()
    return store


def _asked(row) -> list:
    return [m["content"] for m in row["prompt"] if m["role"] == "assistant" and "Ask " in m["content"]]


@SKIP_MODELS
def test_follow_questions_asks_each_chosen_question_once_and_later_rows_see_its_answer(backend, domain, tmp_path, monkeypatch):
    off = _follow_build(backend, domain, tmp_path / "off", False, monkeypatch)
    assert not any(_asked(r) for r in off.rows)  # the rollout is the student's own: no question in any prompt
    on = _follow_build(backend, domain, tmp_path / "on", True, monkeypatch)
    chosen = [r for r in on.rows if r["kind"] == "question"]
    assert chosen and chosen[0]["step"] == 0 and not _asked(on.rows[0])
    first = on.rows[1]  # the step after the first chosen question: asked, answered, in its prompt
    assert _asked(first) == ["Action: " + chosen[0]["question"]]
    reply = first["prompt"][[m["content"] for m in first["prompt"]].index(_asked(first)[0]) + 1]["content"]
    assert reply.startswith("The user replied:") and chosen[0]["answer"] in reply
    for r in on.rows:  # each question asked at most once, and the rejected answer stays the student's own
        assert len(_asked(r)) == len(set(_asked(r))) and r["rejected"][0]["content"] == "Action: Look for bread"
        again = "Action: " + r["question"] in _asked(r)  # a question the user already answered: never chosen
        assert r["kind"] == ("teacher" if again else "question")
    assert any(r["kind"] == "teacher" for r in on.rows)  # the proposer did repeat itself here
    assert [r["question"] for r in chosen] == [q.removeprefix("Action: ") for q in _asked(on.rows[-1])] + (
        [on.rows[-1]["question"]] if on.rows[-1]["kind"] == "question" else [])


@SKIP_MODELS
def test_follow_questions_resumes_as_the_first_run_went(backend, domain, tmp_path, monkeypatch):
    whole = _follow_build(backend, domain, tmp_path / "whole", True, monkeypatch)
    part = tmp_path / "part"
    part.mkdir()
    lines = (tmp_path / "whole" / "pairs.jsonl").read_text().splitlines(keepends=True)
    (part / "pairs.jsonl").write_text("".join(lines[:3]))  # a kill after three steps
    resumed = _follow_build(backend, domain, part, True, monkeypatch)
    assert [r["prompt"] for r in resumed.rows] == [r["prompt"] for r in whole.rows]
