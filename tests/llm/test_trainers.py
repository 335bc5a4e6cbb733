"""`adapt train dpo|sft|no-reflection|star-gate` (adaptbench.training.trainers): settings from a file and flags,
rows in the planner's own tokens, every row's length checked (a long row is reported, never dropped), the
STaR-GATE prompts rebuilt as the planner renders them, and the chain data -> dpo -> rollout --model
OUT/merged end to end; resume after a kill (slow)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from adaptbench.training.trainers.config import (
    DPOSettings,
    NoReflectionSettings,
    SettingsError,
    load_settings,
)

from .conftest import SKIP_MODELS, play

REQUIRED = {"data": "d", "model": "m", "out": "o"}


def test_settings_defaults_are_the_release_s():
    s = load_settings(DPOSettings, REQUIRED)
    assert (s.lora_r, s.lora_alpha, s.beta, s.loss, s.lr) == (4, 16, 0.1, "sigmoid", 1e-4)
    assert s.targets() == ["q_proj", "v_proj"]
    assert load_settings(DPOSettings, REQUIRED | {"lora_targets": "all-linear"}).targets() == "all-linear"


def test_config_file_then_flags_override(tmp_path):
    f = tmp_path / "dpo.yaml"
    f.write_text("data: runs/data\nmodel: models/tiny\nout: runs/dpo\nlr: 2.0e-4\nmax-steps: 30\nloss: ipo\n")
    s = load_settings(DPOSettings, {}, f)
    assert (s.data, s.lr, s.max_steps, s.loss, s.beta) == ("runs/data", 2e-4, 30, "ipo", 0.1)
    s = load_settings(DPOSettings, {"loss": "sigmoid_norm", "max_steps": 5}, f)
    assert (s.loss, s.max_steps, s.lr) == ("sigmoid_norm", 5, 2e-4)  # flags win, the file keeps the rest


def test_cli_flags_reach_the_settings(tmp_path):
    from adaptbench.cli.main import build_parser
    from adaptbench.training.trainers.config import given_flags

    f = tmp_path / "nr.yaml"
    f.write_text("data: a\nmodel: b\nout: c\nno_gain: true\n")
    args = build_parser().parse_args(["train", "no-reflection", "--config", str(f), "--no-no-gain", "--beta", "0.2"])
    s = load_settings(NoReflectionSettings, given_flags(args, NoReflectionSettings), args.config)
    assert (s.no_gain, s.beta, s.out) == (False, 0.2, "c")


@pytest.mark.parametrize(("text", "flags", "says"), [
    ("data: a\nmodel: b\nout: c\nbeta_: 1\n", {}, "unknown setting beta_"),
    ("data: a\nmodel: b\nout: c\nloss: hinge\n", {}, "loss must be one of sigmoid, ipo, sigmoid_norm"),
    ("data: a\nmodel: b\nout: c\nbatch: four\n", {}, "'four' is not a valid batch"),
    ("data: a\nmodel: b\n", {}, "missing --out"),
    ("- a list\n", {}, "expected a mapping"),
    ("data: a\nmodel: b\nout: c\n", {"max_steps": 0}, "--max-steps must be at least 1"),
])
def test_bad_settings_are_named(tmp_path, text, flags, says):
    f = tmp_path / "s.yaml"
    f.write_text(text)
    with pytest.raises(SettingsError, match=says):
        load_settings(DPOSettings, flags, f)


def test_bad_config_is_one_line_and_exit_2(tmp_path, capsys):
    from adaptbench.cli.main import main

    assert main(["train", "dpo", "--config", str(tmp_path / "none.yaml")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("adapt: --config") and err.count("\n") == 1


def _row(step, kind, prompt, chosen="Look for pan", rejected="Look for eggs", reason=None):
    from adaptbench.training.dataset import FIELDS

    return dict.fromkeys(FIELDS) | {"prompt": prompt, "kind": kind, "skip_reason": reason, "persona": "sarah", "task": "eggs", "seed": 0,
            "interaction": 1, "step": step, "truncated": False, "teacher_action": "Look for pan",
            "student_action": rejected, "question": None,
            "chosen": None if kind == "skipped" else [{"role": "assistant", "content": "Action: " + chosen}],
            "rejected": [{"role": "assistant", "content": "Action: " + rejected}]}


def _messages(n_words):
    return [{"role": "system", "content": "You help with breakfast. " + "eggs " * n_words},
            {"role": "user", "content": "What is the next action required to achieve the task: Prepare eggs?"}]


def _pairs(out, rows):
    out.mkdir(parents=True, exist_ok=True)
    (out / "pairs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    (out / "summary.json").write_text("{}\n")


@SKIP_MODELS
def test_rows_are_the_planner_s_tokens_and_methods_pick_their_rows(backend):
    from adaptbench.llm.chat import render
    from adaptbench.llm.prompts import Prompt
    from adaptbench.training.trainers.encode import Encoder
    from adaptbench.training.trainers.rows import dpo_rows, no_reflection_rows, sft_rows

    tok = backend.tokenizer
    rows = [_row(0, "teacher", _messages(5)), _row(1, "question", _messages(5), chosen='Ask "Cheese?"'),
            _row(2, "skipped", _messages(5), reason="no_gain"), _row(3, "skipped", _messages(5), reason="same_action")]
    enc = Encoder(tok)
    d = dpo_rows(rows, enc)
    assert [r.key[-1] for r in d] == [0, 1]
    messages = tuple(rows[0]["prompt"])
    assert list(d[0].prompt) == backend.encode(render(tok, Prompt(messages, "")))  # TRL's layout: the template's
    full = tok.apply_chat_template([*messages, {"role": "assistant", "content": "Action: Look for pan"}], tokenize=False)
    assert list(d[0].prompt + d[0].chosen) == tok(full, add_special_tokens=False)["input_ids"]
    played = backend.encode(render(tok, Prompt(messages, "Action: "))) + tok("Look for pan", add_special_tokens=False)["input_ids"]
    assert list(d[0].prompt + d[0].chosen)[:len(played)] == played  # what the planner reads and writes, then its end
    assert tok.decode(d[1].chosen) == 'Action: Ask "Cheese?"<|end|>\n' and tok.eos_token_id in d[1].chosen
    assert tok.decode(d[0].rejected) == "Action: Look for eggs<|end|>\n"
    assert [r.key[-1] for r in sft_rows(rows, enc)] == [0, 1] and sft_rows(rows, enc)[0].rejected is None
    nr = no_reflection_rows(rows, enc)
    assert [r.key[-1] for r in nr] == [0, 1, 2]  # the question row trains a^t, the no_gain step too
    assert {tok.decode(r.chosen) for r in nr} == {"Action: Look for pan<|end|>\n"}
    assert [r.key[-1] for r in no_reflection_rows(rows, enc, no_gain=False)] == [0, 1]
    generated = dict(rows[0], rejected_token_ids=[5, 6, tok.eos_token_id])  # the student's own ids, as they are
    got = dpo_rows([generated], enc)[0]
    assert got.rejected == (5, 6, tok.eos_token_id) and got.generated_rejected and got.chosen == d[0].chosen


@SKIP_MODELS
def test_a_template_that_renders_the_prompt_otherwise_gets_the_generation_layout(tiny):
    from transformers import AutoTokenizer

    from adaptbench.training.trainers.encode import Encoder

    tok = AutoTokenizer.from_pretrained(tiny)
    tok.chat_template = tok.chat_template.replace("<|assistant|>\n{% endif %}", "<|assistant|>\nthink\n{% endif %}")
    prompt, (chosen,), trl_layout = Encoder(tok).row(_messages(5), "Look for pan")
    assert not trl_layout and tok.decode(prompt).endswith("<|assistant|>\nthink\nAction: ")
    assert list(chosen) == tok("Look for pan", add_special_tokens=False)["input_ids"] + [tok.eos_token_id]


@SKIP_MODELS
def test_the_generation_layout_is_what_the_planner_plays_on(backend):
    from adaptbench.llm.boundary import split_tail
    from adaptbench.llm.chat import render
    from adaptbench.llm.prompts import Prompt
    from adaptbench.training.trainers.encode import Encoder
    from adaptbench.training.trainers.rows import dpo_rows, sft_rows

    tok = backend.tokenizer
    rows = [_row(0, "teacher", _messages(5)), _row(1, "question", _messages(5), chosen='Ask "Cheese?"')]
    rows = [dict(r, rejected_token_ids=[5, 6, tok.eos_token_id]) for r in rows]
    enc = Encoder(tok, "generation")
    d = dpo_rows(rows, enc)
    h = split_tail(tok, render(tok, Prompt(tuple(rows[0]["prompt"]), "Action: ")))
    assert list(d[0].prompt) == backend.encode(h.head)  # the healed prompt the planner reads, prefix and all
    assert tok.decode(d[0].prompt + d[0].chosen).endswith("Action: Look for pan" + tok.eos_token)
    assert "Action" not in tok.decode(d[1].chosen) and tok.decode(d[1].chosen).endswith('Ask "Cheese?"' + tok.eos_token)
    assert tok.decode(d[0].rejected).endswith("Look for eggs" + tok.eos_token) and not d[0].generated_rejected
    assert sft_rows(rows, enc)[1].chosen == d[1].chosen
    with pytest.raises(ValueError, match="unknown row layout 'other'"):
        Encoder(tok, "other")


@SKIP_MODELS
def test_a_run_from_before_a_setting_existed_resumes_with_its_default(tiny, tmp_path):
    from adaptbench.training.trainers.config import DPOSettings
    from adaptbench.training.trainers.run import TrainError, _recorded, check_resume

    s = DPOSettings(data=str(tmp_path), model=str(tiny), out=str(tmp_path / "o"))
    old = {k: v for k, v in _recorded(s).items() if k != "layout"}
    (tmp_path / "settings.json").write_text(json.dumps(old))
    check_resume(s, tmp_path)  # no `layout` recorded: it ran with the default
    with pytest.raises(TrainError, match="layout chat -> generation"):
        check_resume(DPOSettings(data=str(tmp_path), model=str(tiny), out=str(tmp_path / "o"), layout="generation"),
                     tmp_path)


@SKIP_MODELS
def test_data_on_evaluation_seeds_is_refused_unless_asked(tiny, tmp_path):
    data = tmp_path / "data"
    _pairs(data, [_row(0, "teacher", _messages(5)), dict(_row(1, "teacher", _messages(5)), seed=100)])
    args = ("train", "sft", "--data", data, "--model", tiny, "--max-steps", 1, "--batch", 1, "--threads", 1)
    refused = _adapt(*args, "--out", tmp_path / "a")
    said = [x for x in refused.stderr.splitlines() if x.startswith("adapt:")]
    assert refused.returncode == 2 and len(said) == 1 and "evaluation scene seeds 0" in said[0], refused.stderr
    assert "--allow-eval-seeds" in said[0] and not (tmp_path / "a" / "merged").exists()
    allowed = _adapt(*args, "--out", tmp_path / "b", "--allow-eval-seeds")
    assert allowed.returncode == 0, allowed.stderr
    assert json.loads((tmp_path / "b" / "train.json").read_text())["scene_seeds"] == [0, 100]


@SKIP_MODELS
def test_long_row_is_reported_never_dropped(backend, tmp_path):
    from adaptbench.training.trainers import DPOSettings
    from adaptbench.training.trainers.run import TrainError, prepare, report_long

    data = tmp_path / "data"
    _pairs(data, [_row(0, "teacher", _messages(5)), _row(1, "teacher", _messages(3000)),
                  _row(2, "teacher", _messages(8))])
    s = load_settings(DPOSettings, {"data": str(data), "model": "m", "out": str(tmp_path / "o"), "max_length": 600})
    p = prepare("dpo", s, backend.tokenizer)
    assert [r.key[-1] for r in p.rows] == [0, 2] and [r.key[-1] for r in p.long] == [1]
    with pytest.raises(TrainError, match=r"1 of 3 rows do not fit --max-length 600 .*sarah/eggs/seed 0/interaction "
                                         r"1/step 1.*--long-rows skip"):
        report_long(p, s, tmp_path)
    skip = load_settings(DPOSettings, {**vars(s), "long_rows": "skip"})
    assert "left out" in report_long(p, skip, tmp_path)
    listed = [json.loads(x) for x in (tmp_path / "long_rows.jsonl").read_text().splitlines()]
    assert listed[0]["key"] == ["sarah", "eggs", 0, 1, 1] and listed[0]["tokens"] > 600


@SKIP_MODELS
def test_stargate_prompts_are_the_planner_s(domain, backend):
    from dataclasses import replace

    from adaptbench.agents.scripted import OraclePolicy
    from adaptbench.llm.chat import render
    from adaptbench.training.relabel import student_policy
    from adaptbench.training.trainers.encode import Encoder
    from adaptbench.training.trainers.stargate import stargate_rows, top_fraction

    student, oracle = student_policy(backend, domain, budget=1500), OraclePolicy(domain)
    ep, _ = play(domain, task="eggs", persona="juan", steps=(), agent="planner")
    student.start(ep.id, ep.env)
    oracle.start(ep.id, ep.env)
    prompts, steps = [], []
    for _ in range(6):  # the planner's prompt for the history so far; the oracle's action is taken
        view = ep.view()
        prompts.append(student.act_batch([view])[0].prompt)
        turn = ep.apply(oracle.act(view))
        steps.append({"action": turn.action, "observation": turn.observation, "reply": turn.reply})
    record = {"agent": "planner", "persona": "juan", "task": "eggs", "seed": 0, "steps": steps,
              "satisfaction_rate": 0.5, "agent_config": {"budget": 1500}}
    rows, bad = stargate_rows(domain, [record], Encoder(backend.tokenizer), 4096)
    assert bad == 0 and len(rows) == 6
    for row, prompt, step in zip(rows, prompts, steps, strict=True):
        assert list(row.prompt) == backend.encode(render(backend.tokenizer, replace(prompt, prefix="")))
        assert backend.tokenizer.decode(row.chosen) == f"Action: {step['action']}<|end|>\n"
    assert any(p.omitted for p in prompts)  # the budget cut old steps, and the rebuild cut the same ones
    tampered = dict(record, steps=[dict(steps[0], observation="no")] + steps[1:])
    assert stargate_rows(domain, [tampered], Encoder(backend.tokenizer), 4096) == ([], 1)
    recs = [dict(record, persona=p, satisfaction_rate=r) for p, r in [("a", 0.1), ("b", 0.9), ("c", 0.5)]]
    assert [r["persona"] for r in top_fraction(recs, 1 / 3)] == ["b"]
    ties = [dict(record, persona=p, satisfaction_rate=0.0, completed=c) for p, c in [("a", []), ("b", ["eggs"]), ("c", [])]]
    assert [r["persona"] for r in top_fraction(ties, 1 / 3)] == ["b"]  # at equal rates, further along first
    from adaptbench.training.trainers.stargate import split_of

    seen0 = [p for p in domain.persona if p not in domain.splits[0].unseen]
    assert split_of(domain, [dict(record, persona=p) for p in seen0]) == domain.splits[0].id
    assert split_of(domain, [dict(record, persona=p) for p in domain.persona]) is None  # every persona: no split


def _adapt(*args, timeout=240):
    return subprocess.run([sys.executable, "-m", "adaptbench.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, env={**os.environ, "TQDM_DISABLE": "1"})


def _data(tiny, out):
    got = _adapt("train", "data", "--student", tiny, "--out", out, "--personas", "sarah", "--tasks", "eggs",
                 "--split", "1", "--batch", "1", "--max-steps", "12")
    assert got.returncode == 0, got.stderr
    return json.loads((out / "summary.json").read_text())


@SKIP_MODELS
def test_chain_data_dpo_rollout_on_the_merged_model(tiny, tmp_path):
    data, out = tmp_path / "data", tmp_path / "dpo"
    summary = _data(tiny, data)
    assert summary["trainable"] >= 1
    refused = _adapt("train", "dpo", "--data", data, "--model", tiny, "--out", out, "--max-length", 600)
    assert refused.returncode == 1 and "do not fit --max-length 600" in refused.stderr
    assert "Traceback" not in refused.stderr and not (out / "merged").exists()
    got = _adapt("train", "dpo", "--data", data, "--model", tiny, "--out", out, "--max-steps", 2, "--batch", 1,
                 "--logging-steps", 1, "--threads", 1)
    assert got.returncode == 0, got.stderr
    r = json.loads((out / "train.json").read_text())
    assert r["rows"] == summary["trainable"] and r["long_rows_left_out"] == 0 and r["steps"] == 2
    assert r["scene_seeds"] == [100]  # the data's (training scenes), recorded for `adapt eval`
    assert r["rows_with_generated_rejected_ids"] == r["rows"]  # the student's own ids (rejected_token_ids)
    assert r["first"]["loss"] == pytest.approx(0.6931, abs=1e-3)  # log 2: the adapter starts as the reference
    assert r["last"]["rewards/margins"] > 0 and r["last"]["loss"] < r["first"]["loss"]
    assert (out / "adapter" / "adapter_config.json").is_file() and (out / "merged" / "config.json").is_file()
    assert not (out / "merged" / "adapter_config.json").exists()  # a plain model directory
    runs = tmp_path / "merged.jsonl"
    played = _adapt("rollout", "--agent", "planner", "--model", out / "merged", "--personas", "sarah", "--tasks",
                    "eggs", "--seeds", 0, "--max-steps", 2, "--out", runs, "--quiet")
    assert played.returncode == 0, played.stderr
    rec = json.loads(runs.read_text())
    assert rec["agent_config"]["model"] == str(out / "merged") and rec["n_steps"] == 2
    _eval_tables_and_figures(tmp_path, runs)


def test_dpo_with_the_chosen_nll_term(tiny, tmp_path):
    """`--loss sigmoid+sft` (RPO): TRL's DPO loss plus the chosen completion's negative log-likelihood, so the
    first step's loss is log 2 plus that NLL, well above DPO's log 2."""
    data, out = tmp_path / "data", tmp_path / "rpo"
    _data(tiny, data)
    got = _adapt("train", "dpo", "--data", data, "--model", tiny, "--out", out, "--max-steps", 1, "--batch", 1,
                 "--logging-steps", 1, "--threads", 1, "--loss", "sigmoid+sft")
    assert got.returncode == 0, got.stderr
    r = json.loads((out / "train.json").read_text())
    assert r["first"]["loss"] > 0.6931 + 0.5  # the untrained tiny model's NLL of the chosen action is large
    assert json.loads((out / "settings.json").read_text())["loss"] == "sigmoid+sft"


def _eval_tables_and_figures(tmp_path, runs):
    """The chain's last link: `adapt eval` reads the trained model's provenance (OUT/train.json) and puts its
    records in the Reflection-DPO rows of both tables, with both figures drawn."""
    pytest.importorskip("matplotlib")
    md, temporal, questions = tmp_path / "tables.md", tmp_path / "temporal.png", tmp_path / "questions.png"
    got = _adapt("eval", runs, "--markdown", md, "--plot-temporal", temporal, "--plot-questions", questions)
    assert got.returncode == 0, got.stderr
    text = md.read_text()
    assert "**Table 1**" in text and "**Table 2**" in text
    dpo_rows = [line for line in text.splitlines() if line.startswith("| reflection-dpo |")]
    assert len(dpo_rows) == 2 and all("missing" not in line for line in dpo_rows)  # Table 1 and Table 2
    for png in (temporal, questions):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
@SKIP_MODELS
def test_resume_after_kill(tiny, tmp_path):
    data, out = tmp_path / "data", tmp_path / "dpo"
    _data(tiny, data)
    cmd = [sys.executable, "-m", "adaptbench.cli", "train", "dpo", "--data", str(data), "--model", str(tiny),
           "--out", str(out), "--max-steps", "6", "--save-steps", "2", "--batch", "1", "--logging-steps", "1",
           "--precompute-ref", "no"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 300
    while time.time() < deadline and proc.poll() is None and not (out / "checkpoints/checkpoint-2/trainer_state.json").exists():
        time.sleep(0.2)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (out / "train.json").exists()
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    assert "resuming from" in again.stderr and "checkpoint-" in again.stderr
    r = json.loads((out / "train.json").read_text())
    assert r["steps"] == 6 and r["steps_run"] < 6
    other = subprocess.run(cmd[:-2] + ["--lr", "0.5"], capture_output=True, text=True, timeout=120)
    assert other.returncode == 1 and "holds a run with other settings (lr" in other.stderr


@pytest.mark.slow
@SKIP_MODELS
def test_sft_no_reflection_and_star_gate_train_and_merge(tiny, tmp_path):
    from adaptbench.cli.main import main

    data, runs = tmp_path / "data", tmp_path / "student.jsonl"
    summary = _data(tiny, data)
    played = _adapt("rollout", "--agent", "planner", "--model", tiny, "--personas", "sarah,ron", "--tasks", "eggs",
                    "--seeds", 100, "--max-steps", 3, "--out", runs, "--quiet")
    assert played.returncode == 0, played.stderr
    common = ["--model", str(tiny), "--max-steps", "1", "--batch", "2", "--logging-steps", "1"]
    for method, src in (("sft", data), ("no-reflection", data), ("star-gate", runs)):  # runs: seeds 100 (training)
        out = tmp_path / method
        assert main(["train", method, "--data", str(src), "--out", str(out), *common]) == 0
        r = json.loads((out / "train.json").read_text())
        assert r["steps"] == 1 and (out / "merged" / "config.json").is_file()
        if method == "star-gate":  # the top third of 2 rollouts: 1 record of 3 steps
            assert (r["rollouts"], r["rollouts_kept"], r["rows"]) == (2, 1, 3)
        else:
            assert r["rows"] >= summary["trainable"] and r["last"]["loss"] > 0


def test_read_rollouts_takes_one_agent_or_several(tmp_path):
    from adaptbench.training.trainers.rows import DataError
    from adaptbench.training.trainers.stargate import read_rollouts

    def rec(agent, **kw):
        return json.dumps({"agent": agent, "persona": "juan", "task": "eggs", "seed": 0, "steps": [],
                           "satisfaction_rate": 0.5, **kw})

    f = tmp_path / "r.jsonl"
    f.write_text("\n".join([rec("oracle"), rec("oracle-ask"), rec("planner"), rec("oracle", error="boom"),
                            "not json"]) + "\n")
    from adaptbench.training.dataset import BadRows

    with pytest.raises(BadRows, match=r"r.jsonl:5: not JSON"):  # a line that is not a record is named
        read_rollouts(f, "oracle")
    notes = []
    assert [r["agent"] for r in read_rollouts(f, "oracle", skip_bad=True, log=notes.append)] == ["oracle"]
    assert notes and "left out 1 bad row(s)" in notes[0]
    f.write_text("\n".join([rec("oracle"), rec("oracle-ask"), rec("planner"), rec("oracle", error="boom")]) + "\n")
    assert [r["agent"] for r in read_rollouts(f, "oracle")] == ["oracle"]
    assert [r["agent"] for r in read_rollouts(f, "oracle, oracle-ask")] == ["oracle", "oracle-ask"]
    with pytest.raises(DataError, match="no finished rollouts of agent 'react'"):
        read_rollouts(f, "react")


def test_star_gate_on_a_teachers_trajectories_is_recorded_as_teacher_sft():
    """SFT on scripted agents' rollouts is a warm start, not the STaR-GATE baseline: `adapt eval` must not
    put it in STaR-GATE's row."""
    from types import SimpleNamespace

    from adaptbench.training.trainers import recorded_method

    assert recorded_method("star-gate", SimpleNamespace(agent="oracle,oracle-ask")) == "teacher-sft"
    assert recorded_method("star-gate", SimpleNamespace(agent="planner")) == "star-gate"
    assert recorded_method("star-gate", SimpleNamespace(agent="oracle,planner")) == "star-gate"
    assert recorded_method("dpo", SimpleNamespace(agent="oracle")) == "dpo"


def test_first_corrections_keeps_each_episode_s_first_row_of_a_chosen_action():
    from adaptbench.training.trainers.rows import action_of, first_corrections

    m = _messages(2)
    rows = [_row(4, "teacher", m, chosen="Pour water from sink_1 into kettle_0", rejected="Move egg_0 to pan_0"),
            _row(2, "teacher", m, chosen="Pour water from sink_0 into kettle_0", rejected="Look for egg"),
            _row(3, "question", m, chosen='Ask "Cheese?"'), _row(5, "question", m, chosen='Ask "Cheese?"'),
            _row(6, "teacher", m, chosen="Look for bowl"),
            dict(_row(7, "teacher", m, chosen="Pour water from sink_1 into kettle_0"), seed=1),  # another episode
            dict(_row(8, "teacher", m, chosen="Pour water from sink_1 into kettle_0"), interaction=2)]
    kept, left = first_corrections(rows, lambda r: action_of(r["chosen"]))
    assert sorted(r["step"] for r in kept) == [2, 3, 6, 7, 8] and left == 2  # the kettle at step 2, the question at 3
    by_teacher, _ = first_corrections(rows, lambda r: r["teacher_action"])  # no-reflection's a^t: one per episode
    assert sorted(r["step"] for r in by_teacher) == [2, 7, 8]


@SKIP_MODELS
def test_dedupe_corrections_trains_on_the_first_rows_and_says_how_many_it_left_out(tiny, tmp_path):
    from adaptbench.cli.main import main

    m, data = _messages(3), tmp_path / "data"
    _pairs(data, [_row(0, "teacher", m), _row(1, "teacher", m, rejected="Look for bread"),
                  _row(2, "teacher", m, chosen="Look for egg"), _row(3, "question", m, chosen='Ask "Cheese?"')])
    common = ["--data", str(data), "--model", str(tiny), "--max-steps", "1", "--batch", "1", "--threads", "1",
              "--allow-eval-seeds"]
    assert main(["train", "sft", *common, "--out", str(tmp_path / "all")]) == 0
    assert main(["train", "sft", *common, "--out", str(tmp_path / "first"), "--dedupe-corrections"]) == 0
    every, first = (json.loads((tmp_path / d / "train.json").read_text()) for d in ("all", "first"))
    assert every["rows"] == 4 and "repeated_corrections_left_out" not in every
    assert first["rows"] == 3 and first["repeated_corrections_left_out"] == 1


def test_star_gate_refuses_dedupe_corrections(tmp_path):
    from adaptbench.training.trainers import METHODS
    from adaptbench.training.trainers.config import SettingsError, load_settings

    flags = {"data": "d", "model": "m", "out": str(tmp_path), "dedupe_corrections": True}
    with pytest.raises(SettingsError, match="star-gate trains on rollouts"):
        load_settings(METHODS["star-gate"], flags)
    assert load_settings(METHODS["sft"], flags).dedupe_corrections


@SKIP_MODELS
def test_mask_forced_trains_and_says_how_many_tokens_it_skipped(tiny, tmp_path, domain):
    """`--mask-forced`: DPO and SFT train with a bank question's forced tokens out of the loss, every row kept,
    and train.json and settings.json record it."""
    from adaptbench.cli.main import main
    from adaptbench.grammars.index import domain_questions

    m, data = _messages(3), tmp_path / "data"
    question = f'Ask "{domain_questions(domain)[0]}"'
    _pairs(data, [_row(0, "question", m, chosen=question), _row(1, "teacher", m)])
    common = ["--data", str(data), "--model", str(tiny), "--max-steps", "1", "--batch", "2", "--threads", "1",
              "--allow-eval-seeds", "--mask-forced"]
    for method in ("dpo", "sft"):
        assert main(["train", method, *common, "--out", str(tmp_path / method)]) == 0
        r = json.loads((tmp_path / method / "train.json").read_text())
        assert r["rows"] == 2 and r["forced_tokens_masked"] > 5
        assert json.loads((tmp_path / method / "settings.json").read_text())["mask_forced"] is True
