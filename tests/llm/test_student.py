"""The shipped base student: `--model student` names the checkpoint shipped in the package (behaviour-cloned
on the oracle's episodes of split 0's training personas, no questions), which, greedy, makes and serves a
whole meal for a persona it never trained on; `adapt model student` builds one (slow)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from .conftest import SKIP_MODELS


def test_a_name_resolves_to_the_shipped_checkpoint_and_a_path_wins(tmp_path, monkeypatch):
    from adaptbench.llm.named import named_path, resolve_model

    shipped = named_path("student")
    assert (shipped / "config.json").is_file() and (shipped / "model.safetensors").is_file()
    assert (shipped / "tokenizer.json").is_file() and (shipped / "student.json").is_file()
    assert resolve_model("student") == str(shipped)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "student").mkdir()
    assert resolve_model("student") == "student"  # a directory of that name wins over the name
    assert resolve_model("no/such/model") == "no/such/model" and resolve_model(None) is None


@SKIP_MODELS
def test_the_shipped_student_cooks_for_an_unseen_persona(tmp_path, capsys):
    from adaptbench.cli import main

    out = tmp_path / "r.jsonl"
    assert main(["rollout", "--agent", "planner", "--model", "student", "--personas", CASE[0], "--tasks", CASE[1],
                 "--seeds", "0", "--out", str(out), "--quiet"]) == 0
    rec = json.loads(out.read_text().splitlines()[0])
    actions = [s["action"] for s in rec["steps"]]
    assert set(rec["completed"]) == set(CASE[2]), actions  # every dish of the task made and served
    assert actions[-1] == "Declare Done" and rec["questions"] == 0, actions  # the base never asks
    assert sum(s["ok"] for s in rec["steps"]) >= 0.9 * len(rec["steps"]), actions
    from adaptbench.llm.named import named_path

    meta = json.loads((named_path("student") / "student.json").read_text())
    assert meta["split"] == "0" and not set(meta["scene_seeds"]) & {0, 1, 2, 3}  # provenance: scenes kept apart


CASE = ("mark", "cereal_coffee", ("cereal", "coffee"))  # split 0 unseen persona, scene seed 0 (never trained on)


@pytest.mark.slow
@SKIP_MODELS
def test_cli_builds_a_student(tmp_path, capsys):
    """`adapt model student` at smoke scale: teacher data, a tiny model, TRL pretraining (~1 min)."""
    from adaptbench.cli import main

    out = tmp_path / "st"
    argv = ["model", "student", "--out", str(out), "--tasks", "cereal", "--ask-seeds", "100", "--oracle-seeds",
            "101", "--steps", "2", "--hidden", "32", "--layers", "1", "--workers", "1", "--save-every", "1", "--quiet"]
    assert main(argv) == 0
    info = json.loads((out / "student.json").read_text())
    assert info["pretrain"]["episodes"] == 2 * 12 and info["pretrain"]["skipped"] == 0
    lines = [json.loads(x) for f in ("oracle-ask", "oracle") for x in (out / "data" / f"{f}.jsonl").read_text().splitlines()]
    assert {r["persona"] for r in lines}.isdisjoint({"leila", "lisa", "mark", "samantha"})  # split 0's unseen
    assert any(r["questions"] for r in lines if r["agent"] == "oracle-ask")
    assert not any(r["questions"] for r in lines if r["agent"] == "oracle")
    assert Path(out / "model.safetensors").is_file()
    assert (out / "trainer" / "checkpoint-2" / "trainer_state.json").is_file()  # resumable, every --save-every
    capsys.readouterr()
    assert main(argv) == 0 and "already trained" in capsys.readouterr().err  # a finished build: nothing again
    assert main(["model", "student", "--out", str(out), "--split", "9"]) == 2


@pytest.mark.slow
@SKIP_MODELS
def test_cli_continues_a_student_from_init(tmp_path, capsys):
    """`--init` continues from an existing model (its tokenizer and weights: no new tiny model is built),
    e.g. the shipped base student taught to ask on oracle-ask episodes."""
    from adaptbench.cli import main

    out = tmp_path / "st"
    assert main(["model", "student", "--out", str(out), "--init", "student", "--tasks", "cereal", "--ask-seeds", "100",
                 "--oracle-seeds", "none", "--steps", "1", "--workers", "1", "--quiet"]) == 0
    info = json.loads((out / "student.json").read_text())
    from adaptbench.llm.named import named_path

    assert info["settings"]["init"] == str(named_path("student")) and not (out / "init").exists()
    shipped = json.loads((named_path("student") / "student.json").read_text())
    assert set(info["scene_seeds"]) == {100, *shipped["scene_seeds"]}  # the init's scenes count as trained on
    assert (out / "tokenizer.json").read_text() == (named_path("student") / "tokenizer.json").read_text()


def test_init_must_be_a_model(tmp_path, capsys):
    from adaptbench.cli import main

    assert main(["model", "student", "--out", str(tmp_path / "st"), "--init", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "--init" in err and "config.json" in err and "Traceback" not in err


def test_train_commands_take_the_shipped_students_name():
    """`--student student` (adapt train data) and `--model student` (the trainers, GRPO) name the shipped
    checkpoint, as `adapt rollout --model student` does."""
    from types import SimpleNamespace

    from adaptbench.cli.train import _check_data_args
    from adaptbench.llm.named import named_path

    args = SimpleNamespace(student="student", teacher_model=None, workers=1, device="cpu", backend="transformers")
    _check_data_args(args)
    assert args.student == str(named_path("student"))


def test_training_refuses_a_device_it_cannot_train_on(tmp_path, capsys):
    torch = pytest.importorskip("torch")
    from adaptbench.cli import main

    out = str(tmp_path / "st")
    assert main(["model", "student", "--out", out, "--device", "cuda:1"]) == 2
    assert "training runs on cpu or cuda" in capsys.readouterr().err
    if not torch.cuda.is_available():
        assert main(["model", "pretrain", "--model", "student", "--data", __file__, "--out", out,
                     "--device", "cuda"]) == 2
        assert "--device cuda" in capsys.readouterr().err
    assert not Path(out).exists()


def test_data_only_builds_the_teacher_data_and_trains_nothing(tmp_path, capsys):
    """`--data-only`: OUT/data as the training would build it (kept by the same command without the flag,
    e.g. on a GPU machine it is copied to: bench/gpu_student.sh), no model."""
    from adaptbench.cli import main

    out = tmp_path / "st"
    assert main(["model", "student", "--out", str(out), "--tasks", "cereal", "--ask-seeds", "none",
                 "--oracle-seeds", "100", "--workers", "1", "--data-only", "--quiet"]) == 0
    assert "teacher data in" in capsys.readouterr().out
    episodes = (out / "data" / "oracle.jsonl").read_text().splitlines()
    assert len(episodes) == 12  # split 0's 12 training personas x cereal x seed 100
    assert not (out / "student.json").exists() and not (out / "init").exists()


def test_student_rdpo_is_reflection_dpo_from_the_shipped_student():
    """`--model student-rdpo`: its training.json says Reflection-DPO on split 0, from the shipped student's very
    weights (their sha256), on no evaluation scene, with the evaluation it was shipped with."""
    from adaptbench.harness.methods import read_provenance
    from adaptbench.llm.named import named_path, resolve_model
    from adaptbench.training.pretrain import file_sha256 as sha256

    rdpo = named_path("student-rdpo")
    assert resolve_model("student-rdpo") == str(rdpo) and (rdpo / "model.safetensors").is_file()
    prov = read_provenance(str(rdpo))
    assert prov["method"] == "dpo" and str(prov["split"]) == "0" and not set(prov["scene_seeds"]) & {0, 1, 2, 3}
    assert prov["base"]["weights_sha256"] == [sha256(named_path("student") / "model.safetensors")]
    assert prov["weights_sha256"] == sha256(rdpo / "model.safetensors")
    assert {p["personas"] for p in prov["evaluation"]["paired_with_base"]} == {"seen", "unseen"}


@SKIP_MODELS
def test_student_rdpo_rolls_out_and_eval_labels_it(tmp_path, capsys):
    from adaptbench.cli import main

    out = tmp_path / "r.jsonl"
    assert main(["rollout", "--agent", "planner", "--model", "student-rdpo", "--personas", CASE[0], "--tasks",
                 CASE[1], "--seeds", "0", "--out", str(out), "--quiet"]) == 0
    rec = json.loads(out.read_text().splitlines()[0])
    assert rec["steps"] and rec["steps"][-1]["action"] == "Declare Done"
    capsys.readouterr()
    assert main(["eval", str(out), "--no-ceiling"]) == 0
    table = capsys.readouterr().out
    assert "reflection-dpo  reflection-dpo  1" in table  # the method and split from its training.json: unseen


@SKIP_MODELS
def test_cli_builds_a_student_on_templated_replies_in_their_dialogue_several_sequences_an_update(tmp_path, capsys):
    """`--said-seeds` (templated-reply rows), `--rows-context dialogue` and `--accumulate`: the rows are
    written beside the episodes, and the run's settings (what resuming checks) record both choices."""
    from adaptbench.cli import main

    out = tmp_path / "st"
    argv = ["model", "student", "--out", str(out), "--tasks", "cereal", "--ask-seeds", "none", "--oracle-seeds", "none",
            "--said-seeds", "100", "--rows-context", "dialogue", "--accumulate", "3", "--steps", "2", "--hidden", "32",
            "--layers", "1", "--workers", "1", "--quiet"]
    assert main(argv) == 0
    info = json.loads((out / "student.json").read_text())
    assert info["settings"]["said_seeds"] == [100] and info["scene_seeds"] == [100]
    rows = (out / "data" / "said-rows.jsonl").read_text().splitlines()
    assert rows and info["pretrain"]["sequences"] == len(rows) and info["pretrain"]["steps"] == 2
    run = json.loads((out / "trainer" / "pretrain.json").read_text())["settings"]
    assert run["accumulate"] == 3 and run["rows_context"] == "dialogue"
    capsys.readouterr()
    assert main(["model", "student", "--out", str(out), "--accumulate", "0"]) == 2
    assert "--accumulate" in capsys.readouterr().err
