"""`bench/task_rows.py`: each pair's two rows share a key, differ only in the task's line, carry each task's
own oracle first action, and are the contrast pairs `bench/cook_and_read.py` reads."""

from __future__ import annotations

import json

import pytest

from .bench_scripts import bench_script

pytestmark = pytest.mark.paper


def test_pairs_differ_only_in_the_task_and_tasks_with_one_first_action_make_none(domain):
    from adaptbench.llm.prompts import PromptBuilder
    from adaptbench.llm.task_probe import scene

    s = bench_script("task_rows")
    sc = scene(domain, "juan", 100, list(domain.task), PromptBuilder(domain, "planner"))
    rows = s.task_pair_rows(sc)
    pairs = list(zip(rows[::2], rows[1::2], strict=True))
    differing = [(a, b) for a in sc.firsts for b in sc.firsts if a < b and sc.firsts[a] != sc.firsts[b]]
    assert len(pairs) == len(differing) > 0
    for a, b in pairs:
        assert a["key"] == b["key"] and a["task"] < b["task"]
        assert [a["action"], b["action"]] == [sc.firsts[a["task"]], sc.firsts[b["task"]]] and a["action"] != b["action"]
        lines = [set("\n".join(m["content"] for m in r["messages"]).splitlines()) for r in (a, b)]
        assert lines[0] - lines[1] and len(lines[0] ^ lines[1]) <= 2 * len(domain.task[a["task"]].text.splitlines())
        assert domain.task[a["task"]].text in "".join(lines[0] - lines[1])
    only = s.task_pair_rows(sc, only="tea_eggs")
    assert only == [r for a, b in pairs if "tea_eggs" in (a["task"], b["task"]) for r in (a, b)] and only


def test_the_cli_writes_rows_cook_and_read_takes_as_pairs(tmp_path):
    from adaptbench.training.answer_rows import read_rows

    s = bench_script("task_rows")
    out = tmp_path / "rows.jsonl"
    assert s.main(["--out", str(out), "--personas", "juan", "--seeds", "100"]) == 0
    rows = read_rows([out])
    assert rows and len(rows) == len(out.read_text().splitlines()) and len(rows) % 2 == 0
    assert all(json.loads(line)["at"] == "task" for line in out.read_text().splitlines())
    with pytest.raises(SystemExit, match="unknown nobody"):
        s.main(["--out", str(out), "--personas", "nobody"])
    with pytest.raises(SystemExit, match="unknown task tea_toest"):
        s.main(["--out", str(out), "--personas", "juan", "--only", "tea_toest"])
