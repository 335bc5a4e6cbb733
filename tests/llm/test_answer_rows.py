"""Answer-following rows (`training.answer_rows`, `adapt model student --pair-seeds`): both sides of every
probe pair, prompts that differ only in the answer and targets that differ, from training personas only;
on the evaluation seeds they are refused."""

from __future__ import annotations

import importlib.util

import pytest


@pytest.fixture(scope="module")
def rows(domain):
    from adaptbench.training.answer_rows import answer_rows
    from adaptbench.training.student import training_personas

    return answer_rows(domain, training_personas(domain, "0"), [100], tasks=["eggs"])


def test_each_pair_gives_two_rows_that_differ_only_in_the_answer_and_in_the_action(domain, rows):
    assert rows and len(rows) % 2 == 0
    assert {r["at"] for r in rows} == {"recipe", "start"}
    for a, b in zip(rows[::2], rows[1::2], strict=True):
        assert a["key"] == b["key"] and a["at"] == b["at"]
        assert a["action"] != b["action"]
        differ = [i for i, (x, y) in enumerate(zip(a["messages"], b["messages"], strict=True)) if x != y]
        assert len(a["messages"]) == len(b["messages"]) and len(differ) == 1  # the user's answer alone
        assert a["messages"][differ[0]]["role"] == "user"


def test_no_unseen_persona_reaches_the_rows(domain, rows):
    unseen = set({str(k): v for k, v in domain.unseen.items()}["0"])
    named = {side.split(".")[0] for r in rows for side in r["key"].split("/")[2].split(" vs ")}
    assert named and not named & unseen


def test_the_loss_is_on_the_action_and_eos_only(domain, rows, tmp_path):
    if importlib.util.find_spec("transformers") is None:
        pytest.skip("models extra not installed (missing transformers)")
    from transformers import AutoTokenizer

    from adaptbench.llm.tiny import init_tiny
    from adaptbench.training.answer_rows import answer_examples, read_rows, write_rows
    from adaptbench.training.pretrain import IGNORE

    path = tmp_path / "rows.jsonl"
    write_rows(path, rows[:4])
    assert read_rows([path]) == rows[:4]
    tok = AutoTokenizer.from_pretrained(init_tiny(domain, tmp_path / "tiny"))
    for (ids, labels), r in zip(answer_examples(read_rows([path]), tok), rows[:4], strict=True):
        target = [t for t in labels if t != IGNORE]
        assert tok.decode(target[:-1]) == r["action"] and target[-1] == tok.eos_token_id
        assert ids[len(ids) - len(target):] == target


def test_pair_rows_on_the_evaluation_seeds_are_refused(tmp_path, capsys):
    from adaptbench.cli import main

    assert main(["model", "student", "--out", str(tmp_path / "s"), "--ask-seeds", "none", "--oracle-seeds", "none",
                 "--pair-seeds", "0-1"]) == 2
    err = capsys.readouterr().err
    assert "--pair-seeds" in err and "100" in err and "Traceback" not in err
