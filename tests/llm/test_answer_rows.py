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


def test_templated_replies_name_every_option_and_each_reads_back_to_its_own(domain):
    """`said_rows`: a plain reply per option of every asked choice ("I'd like oat milk."), read by the
    always-ask agent as that option alone; the two sides differ only in the reply and act differently, and
    no persona's preference text is a reply."""
    from adaptbench.agents.plans import all_recipes, choice_points
    from adaptbench.llm.probe import asked_for, said_pairs
    from adaptbench.training.answer_rows import said_rows

    pairs = said_pairs(domain, tasks=["eggs"], seeds=[100])
    choices = dict(choice_points(domain, all_recipes(domain, domain.task["eggs"])))
    prefs = {p.answer for per in domain.personas for p in per.preferences}
    assert len({(p.choice, p.a.option) for p in pairs}) > 20
    for p in pairs:
        choice = choices[p.choice]
        for side in (p.a, p.b):
            assert asked_for(domain, choice, side.answer) == ((side.option,) if choice.multi else side.option)
            assert side.answer not in prefs and side.persona == "said"
        assert p.a.action != p.b.action and p.a.option != p.b.option
    rows = said_rows(domain, [100], places=("start",), tasks=["eggs"])
    assert rows and len(rows) % 2 == 0 and {r["at"] for r in rows} == {"start"}
    for a, b in zip(rows[::2], rows[1::2], strict=True):
        differ = [i for i, (x, y) in enumerate(zip(a["messages"], b["messages"], strict=True)) if x != y]
        assert len(differ) == 1 and a["messages"][differ[0]]["content"].startswith("The user replied:")


def test_a_rows_dialogue_starts_at_the_turn_before_its_question_and_keeps_the_reply(rows):
    from adaptbench.training.answer_rows import dialogue

    for r in rows[:40]:
        cut = dialogue(r["messages"])
        assert all(m["role"] != "system" for m in cut) and cut[0]["role"] == "user"
        assert cut[1]["content"].startswith("Action: Ask") and r["messages"][-len(cut):] == cut
        assert any(m["content"].startswith("The user replied:") or "\nThe user replied:" in m["content"] for m in cut)
