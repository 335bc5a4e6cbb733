"""Training reruns change nothing, whole process: a finished `adapt train dpo|sft` run again says it is done
and trains nothing; a run killed at any moment (after a step's log line, while saving the adapter, the
merged model or train.json) resumes to exactly --max-steps with one log line per step; a bad line of
`pairs.jsonl` (`adapt train data` rerun) or of `--data` (the trainers) is named by file:line and stops the
run (exit 2) unless --skip-bad-rows, which counts and reports what it left out. On the tiny model, with
hand-written rows (short prompts: a step takes a fraction of a second)."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

from adaptbench.training.dataset import FIELDS

from .helpers import ROOT, adapt

MISSING = [m for m in ("torch", "transformers", "trl", "peft", "datasets") if importlib.util.find_spec(m) is None]
pytestmark = pytest.mark.skipif(bool(MISSING), reason=f"train extra not installed (missing {', '.join(MISSING)}): "
                                "pip install -e '.[dev,models,train]'")
KILLER = Path(__file__).with_name("train_killer.py")
MEMORY = 8 << 30  # torch maps far more address space than it uses


@pytest.fixture(scope="module")
def tiny(domain, tmp_path_factory):
    """The tiny model's directory."""
    from adaptbench.llm.tiny import init_tiny

    return init_tiny(domain, tmp_path_factory.mktemp("tiny"))


def row(step: int, kind: str = "teacher", **kw) -> dict:
    """A pairs.jsonl row of the dataset contract with a short prompt."""
    base = dict.fromkeys(FIELDS)
    act = lambda t: [{"role": "assistant", "content": "Action: " + t}]  # noqa: E731
    base.update(prompt=[{"role": "system", "content": "You help with breakfast."},
                        {"role": "user", "content": "What is the next action required to achieve the task: eggs?"}],
                kind=kind, chosen=None if kind == "skipped" else act("Look for pan"), rejected=act("Look for eggs"),
                skip_reason="same_action" if kind == "skipped" else None, teacher_action="Look for pan",
                student_action="Look for eggs", persona="sarah", task="eggs", seed=100, interaction=1, step=step,
                truncated=False, prompt_tokens=20)
    base.update(kw)
    return base


def data_dir(path: Path, lines: list) -> Path:
    """A finished `adapt train data` directory holding `lines` (rows, or raw text for a bad line)."""
    path.mkdir(parents=True, exist_ok=True)
    text = "".join((x if isinstance(x, str) else json.dumps(x)) + "\n" for x in lines)
    (path / "pairs.jsonl").write_text(text)
    (path / "summary.json").write_text("{}\n")
    return path


def _train(method, data, tiny, out, steps=4, *extra, moment=None, timeout=120):
    args = ["train", method, "--data", data, "--model", tiny, "--out", out, "--max-steps", steps, "--batch", 1,
            "--logging-steps", 1, "--save-steps", 2, "--threads", 1, *extra]
    if method in ("dpo", "no-reflection"):
        args += ["--precompute-ref", "no"]
    if moment is None:
        return adapt(args, timeout=timeout, memory=MEMORY)
    return subprocess.run([sys.executable, KILLER, moment, *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


def _log_steps(out: Path) -> list:
    return [json.loads(x)["step"] for x in (out / "log.jsonl").read_text().splitlines()]


def _resume_to_the_end(data, tiny, out: Path, moments: tuple) -> None:
    """Kill a 4-step run at each moment in turn, then run it to the end: exactly 4 steps, one log line each,
    the adapter and merged model in place; a rerun then touches nothing."""
    for moment in moments:  # each run killed at the next moment
        got = _train("dpo", data, tiny, out, moment=moment)
        assert got.returncode == -9, (moment, got.stderr[-2000:])
        assert not (out / "train.json").exists()
        if moment == "log:3":  # step 3 logged, its checkpoint (4) not written: resuming trains 3 and 4 again
            assert _log_steps(out) == [1, 2, 3]
    got = _train("dpo", data, tiny, out)
    assert got.returncode == 0, got.stderr[-2000:]
    assert "Traceback" not in got.stderr
    r = json.loads((out / "train.json").read_text())
    assert r["steps"] == 4 and r["rows"] == 3 and r["last"]["step"] == 4
    assert _log_steps(out) == [1, 2, 3, 4]  # one line per step, none twice
    assert (out / "adapter" / "adapter_model.safetensors").is_file()
    assert (out / "merged" / "config.json").is_file() and (out / "merged" / "model.safetensors").is_file()
    assert not [p.name for p in out.iterdir() if p.name.endswith((".partial", ".tmp"))]
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()}
    again = _train("dpo", data, tiny, out)
    assert again.returncode == 0 and "already holds this finished run (4 steps" in again.stderr
    assert "4 steps on 3 rows" in again.stdout
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()} == before  # nothing touched


def test_killed_after_a_log_line_and_while_saving_merged_resumes_to_exactly_max_steps(tiny, tmp_path):
    data = data_dir(tmp_path / "data", [row(0), row(1), row(2, "question")])
    _resume_to_the_end(data, tiny, tmp_path / "dpo", ("log:3", "merged"))


@pytest.mark.slow
@pytest.mark.parametrize("moment", ["adapter", "result"])
def test_killed_while_saving_the_adapter_or_train_json_resumes_to_exactly_max_steps(tiny, tmp_path, moment):
    data = data_dir(tmp_path / "data", [row(0), row(1), row(2, "question")])
    _resume_to_the_end(data, tiny, tmp_path / "dpo", ("log:3", moment))


@pytest.mark.slow
def test_sft_rerun_after_finishing_trains_nothing(tiny, tmp_path):
    data = data_dir(tmp_path / "data", [row(0), row(1)])
    out = tmp_path / "sft"
    assert _train("sft", data, tiny, out, 2).returncode == 0
    again = _train("sft", data, tiny, out, 2)
    assert again.returncode == 0 and "already holds this finished run (2 steps" in again.stderr
    assert json.loads((out / "train.json").read_text())["steps"] == 2 and _log_steps(out) == [1, 2]
    import shutil

    shutil.rmtree(out / "merged")  # a finished run that lost its merged model saves it again, training nothing
    again = _train("sft", data, tiny, out, 2)
    assert again.returncode == 0 and "holds all 2 steps" in again.stderr and (out / "merged" / "config.json").is_file()
    assert json.loads((out / "train.json").read_text())["steps"] == 2 and _log_steps(out) == [1, 2]


BAD = {
    "empty list": ("[]", "a row must be a JSON object (got list)"),
    "no persona": ({k: v for k, v in row(1).items() if k != "persona"}, "pair row lacks persona"),
    "unknown kind": (row(1, kind="teacher_question"), "unknown pair kind 'teacher_question'"),
    "ids outside the vocabulary": (row(1, rejected_token_ids=[5, 10 ** 6]),
                                   "rejected_token_ids holds 1 id(s) outside the vocabulary"),
    "not JSON": ('{"prompt": [', "not JSON"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_data_row_is_named_by_line_and_stops_the_trainer(tiny, tmp_path, case):
    line, says = BAD[case]
    data = data_dir(tmp_path / "data", [row(0), line, row(2)])
    got = _train("dpo", data, tiny, tmp_path / "dpo", 1)
    assert got.returncode == 2, got.stderr[-2000:]
    assert f"{data / 'pairs.jsonl'}:2: {says}" in got.stderr and "--skip-bad-rows" in got.stderr
    assert got.stderr.count("\n") == 1 and "Traceback" not in got.stderr
    assert not (tmp_path / "dpo" / "checkpoints").exists()


def test_skip_bad_rows_leaves_them_out_counted(tiny, tmp_path):
    lines = [row(0)] + [BAD[c][0] for c in sorted(BAD)] + [row(6)]
    data = data_dir(tmp_path / "data", lines)
    out = tmp_path / "dpo"
    got = _train("dpo", data, tiny, out, 1, "--skip-bad-rows")
    assert got.returncode == 0, got.stderr[-2000:]
    assert f"{data / 'pairs.jsonl'}: left out 5 bad row(s) (--skip-bad-rows), line(s) 2, 3, 4, 5, 6" in got.stderr
    r = json.loads((out / "train.json").read_text())
    assert (r["rows"], r["pairs"], r["bad_rows_left_out"]) == (2, 7, 5)


def test_star_gate_names_a_bad_rollout_line(tiny, tmp_path):
    runs = tmp_path / "student.jsonl"
    runs.write_text('{"agent": "planner", "persona": "sarah", "task": "eggs", "seed": 0, "steps": [], '
                    '"satisfaction_rate": 0.5}\nnot json\n')
    got = _train("star-gate", runs, tiny, tmp_path / "sg", 1)
    assert got.returncode == 2 and f"{runs}:2: not JSON" in got.stderr and "Traceback" not in got.stderr
    skip = _train("star-gate", runs, tiny, tmp_path / "sg", 1, "--skip-bad-rows")  # its one record has no step
    assert f"{runs}: left out 1 bad row(s) (--skip-bad-rows), line(s) 2" in skip.stderr
    assert skip.returncode == 1 and "no rows to train star-gate on" in skip.stderr and '"bad_rows_left_out": 1' in skip.stderr


def _data_args(tiny, out, *extra):
    return ["train", "data", "--student", tiny, "--out", out, "--personas", "sarah", "--tasks", "eggs", "--split", 1,
            "--batch", 1, "--max-steps", 2, "--questions", "topics", *extra]


@pytest.mark.parametrize("case", ["empty list", "no persona", "not JSON"])
def test_a_bad_pairs_line_stops_a_data_rerun_untouched(tiny, tmp_path, case):
    out = data_dir(tmp_path / "data", [row(0), BAD[case][0], row(1)])
    (out / "summary.json").unlink()
    before = (out / "pairs.jsonl").read_bytes()
    got = adapt(_data_args(tiny, out), timeout=120, memory=MEMORY)
    assert got.returncode == 2 and f"{out / 'pairs.jsonl'}:2: {BAD[case][1]}" in got.stderr
    assert "Traceback" not in got.stderr and (out / "pairs.jsonl").read_bytes() == before  # nothing cut


@pytest.mark.slow
def test_a_data_rerun_with_skip_bad_rows_keeps_every_good_row(tiny, tmp_path):
    kept = [row(5, persona="ron"), row(6, persona="ron")]  # rows after the bad line are kept, not cut
    out = data_dir(tmp_path / "data", [kept[0], "[]", kept[1], '{"torn": '])
    (out / "summary.json").unlink()
    (out / "pairs.jsonl").write_bytes((out / "pairs.jsonl").read_bytes().rstrip(b"\n"))  # a torn last line
    got = adapt(_data_args(tiny, out, "--skip-bad-rows"), timeout=120, memory=MEMORY)
    assert got.returncode == 0, got.stderr[-2000:]
    assert "left out 1 bad row(s) (--skip-bad-rows), line(s) 2" in got.stderr and "cut a torn last line" in got.stderr
    rows = [json.loads(x) for x in (out / "pairs.jsonl").read_text().splitlines()]
    assert rows[:2] == kept and len(rows) == 4  # the two kept, then this run's two steps
    assert (out / "pairs.jsonl.bad").read_text() == "[]\n"


def test_reopening_pairs_with_skip_bad_rows_keeps_every_good_row_in_place(tmp_path):
    """The store `adapt train data --skip-bad-rows` opens (in process; the whole command: the slow test above)."""
    from adaptbench.training.dataset import BadRows, PairStore

    kept = [row(5), row(6), row(7)]
    lines = [json.dumps(kept[0]), "[]", json.dumps(kept[1]), json.dumps({k: v for k, v in kept[2].items()
                                                                        if k != "persona"}), json.dumps(kept[2])]
    path = tmp_path / "pairs.jsonl"
    path.write_text("\n".join(lines) + "\n" + '{"torn": ')
    with pytest.raises(BadRows, match=r"pairs.jsonl:2: a row must be a JSON object .*pairs.jsonl:4: pair row lacks "
                                      r"persona"):
        PairStore(tmp_path)
    notes = []
    store = PairStore(tmp_path, skip_bad=True, log=notes.append)
    assert store.rows == kept and len(notes) == 2
    assert "cut a torn last line" in notes[0] and "left out 2 bad row(s) (--skip-bad-rows), line(s) 2, 4" in notes[1]
    assert path.read_text() == "".join(json.dumps(r) + "\n" for r in kept)  # the good lines byte for byte, in order
    assert (tmp_path / "pairs.jsonl.bad").read_text().splitlines() == [lines[1], lines[3]]
    assert PairStore(tmp_path).rows == kept  # clean now
