"""The `adapt` command end to end: scene, replay (text and JSON), play, schema, matrix, exit codes."""

from __future__ import annotations

import io
import json

import pytest

from adaptbench.cli import main

from .conftest import ROOT, SPEC

EXAMPLE = ROOT / "examples" / "toast_coffee.txt"


def test_scene_json(capsys):
    assert main(["scene", "--seed", "3", "--json", "--spec", str(SPEC)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["seed"] == 3 and data["scene_id"].startswith("scene-")
    assert {o["id"] for o in data["objects"]} >= {"kitchen", "fridge_0", "salt_shaker_0"}


def test_replay_json_has_steps_verdicts_rate_and_questions(capsys):
    assert main(["replay", "--task", "toast_coffee", "--persona", "juan", "--full-scene", str(EXAMPLE), "--json",
                 "--spec", str(SPEC)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["steps"][0] == {"action": "Look for eggs", "ok": True, "observation": data["steps"][0]["observation"],
                                "reply": ""}
    assert all(s["ok"] for s in data["steps"])
    assert {p["verdict"] for p in data["preferences"]} <= {"satisfied", "violated", "inapplicable"}
    assert 0 <= data["satisfaction_rate"] <= 1 and data["questions"] == 0
    assert data["completed"] == ["toast", "coffee"]


def test_replay_text_prints_steps_and_table(capsys):
    assert main(["replay", "--task", "toast_coffee", "--persona", "juan", "--full-scene", str(EXAMPLE),
                 "--spec", str(SPEC)]) == 0
    out = capsys.readouterr().out
    assert "[ 1] ok  Look for eggs" in out and "verdict" in out and "questions 0" in out


def test_replay_unknown_persona_is_a_usage_error(capsys):
    assert main(["replay", "--task", "eggs", "--persona", "nobody", "--seed", "0", str(EXAMPLE),
                 "--spec", str(SPEC)]) == 2
    assert "unknown persona 'nobody'" in capsys.readouterr().err


def test_replay_missing_file_is_a_usage_error(capsys, tmp_path):
    assert main(["replay", "--task", "eggs", "--persona", "juan", "--seed", "0", str(tmp_path / "nope.txt"),
                 "--spec", str(SPEC)]) == 2


def test_play_reads_actions_and_prints_verdicts(monkeypatch, capsys):
    monkeypatch.setattr("sys.stdin", io.StringIO("help\nLook for eggs\nAsk \"How do you like your eggs?\"\n"
                                                 "Declare Done\n"))
    assert main(["play", "--task", "eggs", "--persona", "juan", "--full-scene", "--spec", str(SPEC)]) == 0
    out = capsys.readouterr().out
    assert out.index("- kitchen (kitchen)") < out.index("- patio (patio)")
    assert "Found egg_carton_0" in out and "user:" in out and "VIOLATED" in out


def test_schema_writes_every_kind(tmp_path, capsys):
    assert main(["schema", "--out", str(tmp_path)]) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["actions.schema.json", "engine.schema.json", "objects.schema.json", "persona.schema.json",
                     "splits.schema.json", "tasks.schema.json"]
    assert json.loads((tmp_path / "persona.schema.json").read_text())["additionalProperties"] is False


def test_validate_matrix(capsys):
    assert main(["validate", str(SPEC), "--matrix"]) == 0
    out = capsys.readouterr().out
    header = next(line for line in out.splitlines() if line.startswith("persona "))
    assert header.split()[:3] == ["persona", "eggs", "omelette"]
    assert any(line.startswith("juan ") for line in out.splitlines())


def test_no_command_prints_help(capsys):
    assert main([]) == 2
    assert "validate" in capsys.readouterr().out


@pytest.mark.parametrize("argv", [["rollout", "--agent", "wizard", "--out", "x.jsonl"],
                                  ["rollout", "--agent", "oracle", "--personas", "nobody", "--out", "x.jsonl"]])
def test_rollout_bad_names_are_usage_errors(argv, capsys):
    assert main(argv + ["--spec", str(SPEC)]) == 2


def test_play_reads_the_verb_in_any_case_and_a_mistyped_line_uses_no_step(monkeypatch, capsys):
    """`adapt play`: `look for eggs` is `Look for eggs`; `Cook eggs` is no action, uses no step and names the
    cook form with the pan the player has seen; the step numbers show what counted (docs/agents.md)."""
    lines = "look for pan\nLOOK FOR eggs\nMove egg_0 to pan_1\nCook eggs\nTurn on stove_9\nDeclare Done\n"
    monkeypatch.setattr("sys.stdin", io.StringIO(lines))
    assert main(["play", "--task", "eggs", "--persona", "juan", "--full-scene"]) == 0
    out = capsys.readouterr().out
    assert "[ 1] ok  Look for pan" in out and "[ 2] ok  Look for eggs" in out
    assert "[ 3] ok  Move egg_0 to pan_1" in out
    assert "not an action (no step used): did you mean 'Cook items in pan_1 to get cooked_eggs'?" in out
    assert "[ 4] ERR Turn on stove_9" in out  # parses, fails: a step, as in rollouts
    assert "[ 5] ok  Declare Done" in out
    assert "Look for apple" not in out
