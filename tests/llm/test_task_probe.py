"""The task probe (`adapt probe tasks`): each task's step-0 prompt scored on every task's first oracle action;
a stand-in that reads the task gets every prompt right, one that ignores it at most the largest group of
tasks sharing a first action; the CLI prints the table and refuses what it cannot probe in one line."""

from __future__ import annotations

import json

import pytest

from .conftest import SKIP_MODELS

pytestmark = pytest.mark.paper


def _reader(domain, firsts: dict):
    """A scorer that finds the task's line in the prompt and prefers that task's first action."""
    def score(prompt, actions):
        text = " ".join(m["content"] for m in prompt.messages)
        task = next(t for t in firsts if domain.task[t].text in text)
        return tuple(1.0 if a == firsts[task] else 0.0 for a in actions)
    return score


def test_a_model_that_reads_the_task_gets_every_prompt_and_one_that_ignores_it_at_most_the_ceiling(domain):
    from adaptbench.llm.task_probe import first_actions, probe_tasks

    tasks = list(domain.task)
    firsts = first_actions(domain, "mark", 0, tasks)
    assert set(firsts) == set(tasks) and all(isinstance(a, str) and a for a in firsts.values())
    reads = probe_tasks(_reader(domain, firsts), domain, ["mark"], [0], tasks)
    assert reads.prompts == len(tasks) and reads.share == 1.0
    blind = probe_tasks(lambda prompt, actions: tuple(range(len(actions))), domain, ["mark"], [0], tasks)
    assert blind.share <= blind.ignoring < 1.0
    assert sum(sum(c.values()) for c in blind.chosen.values()) == len(tasks)
    assert len({a for c in blind.chosen.values() for a in c}) == 1  # one action in every prompt


def test_task_prompts_differ_only_in_the_task(domain):
    from adaptbench.llm.prompts import PromptBuilder
    from adaptbench.llm.task_probe import scene

    sc = scene(domain, "mark", 0, ["tea_eggs", "tea_toast"], PromptBuilder(domain, "planner"))
    a, b = ("\n".join(m["content"] for m in sc.prompts[t].messages) for t in ("tea_eggs", "tea_toast"))
    assert a != b and a.replace(domain.task["tea_eggs"].text, domain.task["tea_toast"].text) == b


@SKIP_MODELS
def test_cli_probes_tasks_and_refuses_in_one_line(tiny, capsys):
    from adaptbench.cli import main

    assert main(["probe", "tasks", "--model", str(tiny), "--tasks", "eggs,cereal,tea_toast", "--seeds", "0",
                 "--quiet", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    row = out["models"][0]
    assert row["prompts"] == 3 and 0.0 <= row["share"] <= 1.0 and set(row["by_task"]) == {"eggs", "cereal", "tea_toast"}
    assert main(["probe", "tasks", "--model", str(tiny), "--tasks", "eggs", "--quiet"]) == 2
    assert "at least two tasks" in capsys.readouterr().err
    assert main(["probe", "tasks", "--model", "no/such/model", "--quiet"]) == 2
    assert "no such model directory" in capsys.readouterr().err
