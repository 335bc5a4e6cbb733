"""`adapt train reproduce` (training.pipeline): stages in order with done-markers, the estimate printed
before anything runs, resumption after SIGKILL at a stage boundary and in the middle of a stage (fast, on
stand-in stages); the whole smoke pipeline end to end as its own process, killed and resumed (slow)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from ..faults.helpers import sigint_as_in_a_terminal
from .conftest import SKIP_MODELS

ROOT = Path(__file__).resolve().parents[2]

# A stand-in pipeline: stage i appends a line to log.txt, sleeps `nap` seconds (mid-stage), then writes its
# output; its done-marker follows. Run as its own process so that a test can SIGKILL it.
DRIVER = textwrap.dedent("""
    import sys
    from pathlib import Path
    from adaptbench.training.pipeline import Stage, run

    out, nap = Path(sys.argv[1]), sys.argv[2]
    script = ("import sys, time, pathlib; o = pathlib.Path(sys.argv[1]); "
              "(o / 'log.txt').open('a').write(sys.argv[2] + chr(10)); time.sleep(float(sys.argv[3])); "
              "(o / sys.argv[2] / 'out.txt').write_text('made')")
    stages = [Stage(n, (("step", n),), (("start", 1),)) for n in ("a", "b", "c")]
    run(stages, out, log=lambda m: print(m, flush=True),
        runner=lambda cmd: [sys.executable, "-c", script, str(out), cmd[1], nap if cmd[1] == "b" else "0"])
    print("all done", flush=True)
""")


def _driver(tmp_path, nap: str):
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    (tmp_path / "driver.py").write_text(DRIVER)
    return subprocess.Popen([sys.executable, str(tmp_path / "driver.py"), str(tmp_path / "out"), nap], env=env,
                            stdout=subprocess.PIPE, text=True, start_new_session=True)


def _kill_when(proc, cond, timeout: float = 60) -> None:
    t0 = time.time()
    while not cond():
        assert proc.poll() is None and time.time() - t0 < timeout, "the driver ended before the kill point"
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)  # the pipeline and the stage it runs
    proc.wait()


def test_the_estimate_comes_first_and_every_stage_runs_once_in_order(tmp_path):
    p = _driver(tmp_path, "0")
    text, _ = p.communicate(timeout=120)
    lines = text.splitlines()
    assert p.returncode == 0 and lines[0].startswith("estimate: ~") and lines[-1] == "all done"
    assert (tmp_path / "out" / "log.txt").read_text().split() == ["a", "b", "c"]
    for n in "abc":
        marker = json.loads((tmp_path / "out" / n / "done.json").read_text())
        assert marker["commands"] == [["step", n]] and marker["seconds"] >= 0
    rerun = _driver(tmp_path, "0")
    text, _ = rerun.communicate(timeout=120)
    assert "stage a: done (skipped)" in text and "stage c: done (skipped)" in text
    assert (tmp_path / "out" / "log.txt").read_text().split() == ["a", "b", "c"]  # nothing ran again


def test_a_sigkill_mid_stage_resumes_at_that_stage(tmp_path):
    out = tmp_path / "out"
    p = _driver(tmp_path, "30")
    _kill_when(p, lambda: (out / "log.txt").is_file() and "b" in (out / "log.txt").read_text().split())
    assert (out / "a" / "done.json").is_file() and not (out / "b" / "done.json").exists()
    q = _driver(tmp_path, "0")
    text, _ = q.communicate(timeout=120)
    assert q.returncode == 0 and "stage a: done (skipped)" in text
    assert (out / "log.txt").read_text().split() == ["a", "b", "b", "c"]  # b again (killed), a not
    assert all((out / n / "done.json").is_file() for n in "abc")


def test_a_sigkill_at_a_stage_boundary_resumes_at_the_next_stage(tmp_path):
    out = tmp_path / "out"
    p = _driver(tmp_path, "30")
    _kill_when(p, lambda: (out / "a" / "done.json").is_file())  # a finished, b not yet done
    q = _driver(tmp_path, "0")
    q.communicate(timeout=120)
    log = (out / "log.txt").read_text().split()
    assert log.count("a") == 1 and log[-1] == "c" and q.returncode == 0


def test_a_marker_of_other_commands_does_not_count_as_done(tmp_path):
    from adaptbench.training.pipeline import Stage

    st = Stage("a", (("x", "1"),), ())
    (tmp_path / "a").mkdir()
    st.marker(tmp_path).write_text(json.dumps({"commands": [["x", "2"]]}))
    assert not st.done(tmp_path)
    st.marker(tmp_path).write_text(json.dumps({"commands": [["x", "1"]]}))
    assert st.done(tmp_path)


def test_the_plan_keeps_training_off_the_evaluation_seeds_and_personas(domain, tmp_path):
    from adaptbench.harness.rollout import parse_seeds
    from adaptbench.training.pipeline import SCALES, estimate_lines, stages

    for scale in SCALES.values():
        plan = stages(domain, "0", scale, tmp_path)
        assert [s.name for s in plan] == ["base", "eval-base", "pairs", "dpo", "no-reflection", "sft", "star-gate",
                                          "report"]
        training = [c for st in plan for c in st.commands
                    if "--out" in c and not c[c.index("--out") + 1].startswith(str(tmp_path / "eval"))]
        assert {c[1] for c in training} >= {"student", "data", "dpo", "no-reflection", "sft", "star-gate", "--agent"}
        for st in plan:
            for cmd in (c for c in st.commands if c in training):
                for flag in ("--seeds", "--oracle-seeds"):
                    if flag in cmd:
                        assert min(parse_seeds(cmd[cmd.index(flag) + 1])) >= 100
                if "--personas" in cmd:
                    assert set(cmd[cmd.index("--personas") + 1].split(",")).isdisjoint(domain.unseen[0])
        evaluation = [c for st in plan for c in st.commands if c not in training and c[0] == "rollout"]
        assert [st.name for st in plan if set(st.commands) & set(evaluation)] == ["eval-base", "dpo", "no-reflection",
                                                                                   "sft", "star-gate"]
        assert estimate_lines(plan, tmp_path)[0].startswith("estimate: ~")


def test_train_steps_sets_every_trainer_s_steps(capsys, tmp_path):
    from adaptbench.cli import main

    def dpo_estimate(*extra):
        assert main(["train", "reproduce", "--split", "0", "--out", str(tmp_path / "r"), "--scale", "session",
                     "--estimate", *extra]) == 0
        return next(x for x in capsys.readouterr().out.splitlines() if x.split()[0] == "dpo")

    assert dpo_estimate() == "  dpo            ~52 min" and dpo_estimate("--train-steps", "50") == "  dpo            ~22 min"
    assert main(["train", "reproduce", "--split", "0", "--out", str(tmp_path / "r"), "--train-steps", "0"]) == 2
    assert "--train-steps must be at least 1" in capsys.readouterr().err


def test_an_unknown_split_is_one_line(capsys, tmp_path):
    from adaptbench.cli import main

    assert main(["train", "reproduce", "--split", "9", "--out", str(tmp_path / "r")]) == 2
    assert "unknown split '9'" in capsys.readouterr().err


@pytest.mark.slow
@SKIP_MODELS
def test_the_smoke_pipeline_end_to_end_killed_mid_stage_and_resumed(tmp_path):
    """The real thing at smoke scale (a few minutes): killed with SIGKILL while a stage runs, then run again
    to the end: tables and both figures."""
    out = tmp_path / "rep"
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    cmd = [sys.executable, "-m", "adaptbench.cli", "train", "reproduce", "--split", "0", "--scale", "smoke",
           "--out", str(out)]
    p = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                         start_new_session=True)
    first = p.stdout.readline()
    assert first.startswith("estimate: ~"), first
    _kill_when(p, lambda: (out / "pairs" / "pairs.jsonl").is_file(), timeout=600)  # in the pairs stage
    assert (out / "base" / "done.json").is_file() and not (out / "pairs" / "done.json").exists()
    r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=1200)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stderr.splitlines()[0].startswith("estimate: ~") and "stage base: done (skipped)" in r.stderr
    tables = (out / "report" / "tables.md").read_text()
    for method in ("planner", "react", "reflection-dpo", "no-reflection", "no-dpo", "star-gate", "always-ask-llm"):
        assert method in tables
    assert (out / "report" / "temporal.png").stat().st_size > 0 and (out / "report" / "questions.png").is_file()
    info = json.loads((out / "base" / "student.json").read_text())
    assert info["settings"]["split"] == "0" and info["settings"]["ask_seeds"] == []


def test_a_sigkill_of_the_pipeline_alone_ends_its_stage_too(tmp_path):
    out = tmp_path / "out"
    p = _driver(tmp_path, "30")
    t0 = time.time()
    while not ((out / "log.txt").is_file() and "b" in (out / "log.txt").read_text().split()):
        assert time.time() - t0 < 60
        time.sleep(0.05)
    p.kill()  # the pipeline's process only, not its group
    p.wait()
    time.sleep(1)
    ps = subprocess.run(["ps", "-o", "stat=", "-g", str(p.pid)], capture_output=True, text=True).stdout.split()
    assert [s for s in ps if not s.startswith("Z")] == [], ps  # the stage b child died with it (a zombie at most)


def _base(tmp_path, split="0", seeds=(100,), name="base"):
    """A stand-in trained base student: the files `--base` asks for and a student.json."""
    d = tmp_path / name
    d.mkdir()
    for f in ("config.json", "tokenizer_config.json"):
        (d / f).write_text("{}")
    (d / "model.safetensors").write_bytes(b"weights of " + name.encode())
    (d / "student.json").write_text(json.dumps({"split": split, "scene_seeds": list(seeds), "teacher": "oracle"}))
    return d


def test_a_given_base_replaces_the_base_stage_and_every_later_stage_uses_it(domain, tmp_path):
    from adaptbench.training.pipeline import SCALES, check_base, run, stages

    given = check_base(_base(tmp_path), "0")
    assert given["base"] == str((tmp_path / "base").resolve()) and given["student"]["scene_seeds"] == [100]
    out = tmp_path / "rep"
    plan = stages(domain, "0", SCALES["smoke"], out, base=given)
    assert plan[0].name == "base" and plan[0].commands == () and plan[0].given == given
    uses = [c[c.index(f) + 1] for st in plan[1:] for c in st.commands for f in ("--student", "--model") if f in c]
    assert given["base"] in uses and str(out / "base") not in uses  # pairs, trainers, star-gate, eval: the given base
    said = []
    run(plan[:1], out, log=said.append)
    marker = json.loads((out / "base" / "done.json").read_text())
    assert marker["given"] == given and plan[0].done(out) and any("given" in m for m in said)
    other = stages(domain, "0", SCALES["smoke"], out, base=check_base(_base(tmp_path, name="other"), "0"))
    assert not other[0].done(out) and not stages(domain, "0", SCALES["smoke"], out)[0].done(out)


@pytest.mark.parametrize("split,seeds,says", [("1", (100,), "trained for split 1, not --split 0"),
                                              ("0", (2, 100), "trained on scene seed(s) 2"),
                                              (None, None, "no student.json")])
def test_a_base_of_another_split_or_on_evaluation_seeds_is_one_line(split, seeds, says, capsys, tmp_path):
    from adaptbench.cli import main

    base = _base(tmp_path, split, seeds or ())
    if split is None:
        (base / "student.json").unlink()
    assert main(["train", "reproduce", "--split", "0", "--base", str(base), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and len(err.splitlines()) == 1 and err.startswith("adapt: --base ")
    assert not (tmp_path / "r").exists()


def test_the_estimate_with_a_given_base_trains_no_base(capsys, tmp_path):
    from adaptbench.cli import main

    assert main(["train", "reproduce", "--split", "0", "--base", str(_base(tmp_path)), "--out", str(tmp_path / "r"),
                 "--scale", "session", "--estimate"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].split()[:2] == ["base", "~0"] and "given" in lines[1]


def test_the_session_scale_is_the_measured_base_recipe(domain, tmp_path):
    from adaptbench.training.pipeline import SCALES, stages

    cmd = stages(domain, "0", SCALES["session"], tmp_path)[0].commands[0]
    arg = {f: cmd[cmd.index(f) + 1] for f in ("--hidden", "--layers", "--steps", "--oracle-seeds", "--lr")}
    assert arg == {"--hidden": "128", "--layers": "4", "--steps": "4000", "--oracle-seeds": "100-123", "--lr": "0.002"}
    units = dict(stages(domain, "0", SCALES["session"], tmp_path)[0].units)
    assert units["teacher_episode"] == 12 * 8 * 24 == 2304


# A stand-in pipeline run side by side (--jobs 2): a; then b and c, which need only a; then d, which needs
# every stage before it. Each stage logs "<name>+" when it starts and "<name>-" when it ends, sleeping
# `nap` seconds between; a stage named in `fail` exits 3 after its nap.
SIDE_DRIVER = textwrap.dedent("""
    import sys
    from pathlib import Path
    from adaptbench.training.pipeline import Stage, StageFailed, run

    out, nap, fail = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
    script = ("import sys, time, pathlib; o = pathlib.Path(sys.argv[1]); log = (o / 'log.txt').open('a'); "
              "log.write(sys.argv[2] + '+' + chr(10)); log.flush(); time.sleep(float(sys.argv[3])); "
              "log.write(sys.argv[2] + '-' + chr(10)); log.flush(); sys.exit(3 if sys.argv[2] == sys.argv[4] else 0)")
    stages = [Stage("a", (("step", "a"),), (("start", 1),), after=()),
              Stage("b", (("step", "b"),), (("start", 1),), after=("a",)),
              Stage("c", (("step", "c"),), (("start", 1),), after=("a",)),
              Stage("d", (("step", "d"),), (("start", 1),))]
    try:
        run(stages, out, log=lambda m: print(m, flush=True), jobs=2,
            runner=lambda cmd: [sys.executable, "-c", script, str(out), cmd[1], nap if cmd[1] in "bc" else "0", fail])
    except StageFailed as exc:
        print("failed:", exc, flush=True)
        sys.exit(1)
    print("all done", flush=True)
""")


def _side(tmp_path, nap: str, fail: str = "-"):
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    (tmp_path / "side.py").write_text(SIDE_DRIVER)
    return subprocess.Popen([sys.executable, str(tmp_path / "side.py"), str(tmp_path / "out"), nap, fail], env=env,
                            stdout=subprocess.PIPE, text=True, start_new_session=True, preexec_fn=sigint_as_in_a_terminal)


def _until_b_and_c_run(p, out) -> float:
    """Wait until stages b and c both run (side by side); the time the wait began."""
    t0 = time.time()
    while not {"b+", "c+"} <= set(_log(out)):
        assert p.poll() is None and time.time() - t0 < 60
        time.sleep(0.05)
    return t0


def _log(out) -> list:
    return (out / "log.txt").read_text().split() if (out / "log.txt").is_file() else []


def test_stages_that_do_not_need_each_other_run_side_by_side_and_the_rest_waits(tmp_path):
    p = _side(tmp_path, "2")
    text, _ = p.communicate(timeout=120)
    log = _log(tmp_path / "out")
    assert p.returncode == 0 and text.splitlines()[-1] == "all done", text
    assert log[:2] == ["a+", "a-"] and log[-2:] == ["d+", "d-"]
    assert set(log[2:4]) == {"b+", "c+"}  # both started before either ended
    assert "2 stages at a time" in text.splitlines()[0]
    assert "stage b: done in" in text and "stage c: done in" in text
    rerun = _side(tmp_path, "0")
    text, _ = rerun.communicate(timeout=120)
    assert rerun.returncode == 0 and text.count("done (skipped)") == 4 and len(_log(tmp_path / "out")) == 8


def test_a_failed_stage_lets_its_neighbour_finish_and_starts_nothing_after_it(tmp_path):
    p = _side(tmp_path, "1", fail="b")
    text, _ = p.communicate(timeout=120)
    out = tmp_path / "out"
    assert p.returncode == 1 and "failed: stage b" in text, text
    assert (out / "c" / "done.json").is_file() and not (out / "b" / "done.json").exists()
    assert "d+" not in _log(out)
    again = _side(tmp_path, "0")  # fixed: the rerun runs b and d only
    text, _ = again.communicate(timeout=120)
    assert again.returncode == 0 and "stage c: done (skipped)" in text and _log(out)[-4:] == ["b+", "b-", "d+", "d-"]


def test_ctrl_c_stops_every_stage_running_side_by_side(tmp_path):
    out = tmp_path / "out"
    p = _side(tmp_path, "60")
    t0 = _until_b_and_c_run(p, out)
    p.send_signal(signal.SIGINT)  # the pipeline alone: its stages did not get the Ctrl-C
    p.communicate(timeout=30)
    assert p.returncode != 0 and time.time() - t0 < 40
    time.sleep(0.5)
    ps = subprocess.run(["ps", "-o", "stat=", "-g", str(p.pid)], capture_output=True, text=True).stdout.split()
    assert [s for s in ps if not s.startswith("Z")] == [], ps
    assert not (out / "b" / "done.json").exists() and not (out / "c" / "done.json").exists()


def test_a_sigkill_of_the_pipeline_ends_the_stages_it_runs_side_by_side(tmp_path):
    out = tmp_path / "out"
    p = _side(tmp_path, "60")
    _until_b_and_c_run(p, out)
    p.kill()  # the pipeline's process only; each stage's child was started from a thread of it
    p.wait()
    time.sleep(1)
    ps = subprocess.run(["ps", "-o", "stat=", "-g", str(p.pid)], capture_output=True, text=True).stdout.split()
    assert [s for s in ps if not s.startswith("Z")] == [], ps


def test_the_estimate_of_stages_side_by_side_is_the_schedule_s_length(tmp_path):
    from adaptbench.training.pipeline import Stage, estimate_lines, makespan

    def st(name, after, n):
        return Stage(name, (("x", name),), (("start", n),), costs="h32-l1", after=after)

    plan = [st("a", (), 1), st("b", ("a",), 3), st("c", ("a",), 2), st("d", ("a",), 2), st("e", None, 1)]
    sec = 10.0  # COSTS["h32-l1"]["start"]
    assert makespan(plan, tmp_path, jobs=1) == 9 * sec
    assert makespan(plan, tmp_path, jobs=2) == (1 + 4 + 1) * sec  # b alone; c then d beside it; e after all
    assert makespan(plan, tmp_path, jobs=3) == (1 + 3 + 1) * sec
    (tmp_path / "a").mkdir()
    plan[0].marker(tmp_path).write_text(json.dumps({"commands": [["x", "a"]], "given": None}))
    assert makespan(plan, tmp_path, jobs=2) == 5 * sec
    assert estimate_lines(plan, tmp_path, jobs=2)[0].startswith("estimate: ~50 s for the stages left")
