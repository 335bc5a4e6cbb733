"""`adapt train data --backend openai`: the student generating and scoring on a served engine gives the
rows the local backend gives (same prompts, actions, questions, ids; Δq/Δt from the server's prompt
log-probabilities equal within float tolerance), against the fake OpenAI-compatible server over the shipped
tiny student (`fake_server.py` answering in vLLM's `prompt_logprobs` form; question and teacher rows, the answered prompts and two steps' scores in one batch are all compared); a server that cannot be used is one
line and exit 2. The same against a real vLLM: `test_vllm.py`."""

from __future__ import annotations

import json

import pytest

from adaptbench.cli import main

from .conftest import SKIP_MODELS

pytestmark = SKIP_MODELS
SCORES = ("p_teacher", "p_teacher_given_answer", "p_student", "delta_q", "delta_t")
# tea and eggs, where the shipped base student (which never learnt to ask) departs from the teacher; questions
# about the teacher's named preference (`topics`) and ε1 0.1, so that some (Δq up to 0.13 here) make question
# rows as well as teacher rows
SELECTION = ("--personas", "ron", "--tasks", "tea_eggs", "--split", "1", "--seeds", "100-101", "--max-steps", "3",
             "--batch", "2", "--eps1", "0.1", "--questions", "topics")


def build(student, out, *extra) -> list:
    """`adapt train data` on the selection; its rows."""
    assert main(["train", "data", "--student", str(student), "--out", str(out), *SELECTION, *extra]) == 0
    return [json.loads(line) for line in (out / "pairs.jsonl").read_text().splitlines()]


def same_rows(served: list, local: list, tol: float) -> float:
    """Assert the served rows are the local rows (every field but the scores equal, the scores within
    `tol`); the largest score difference."""
    assert len(served) == len(local) > 0
    worst = 0.0
    for a, b in zip(served, local, strict=True):
        assert {k: v for k, v in a.items() if k not in (*SCORES, "score_dtype")} == \
            {k: v for k, v in b.items() if k not in (*SCORES, "score_dtype")}
        for k in SCORES:
            assert (a[k] is None) == (b[k] is None), k
            if a[k] is not None:
                worst = max(worst, abs(a[k] - b[k]))
                assert a[k] == pytest.approx(b[k], abs=tol), k
    return worst


@pytest.fixture(scope="module")
def student():
    """(the shipped student's directory, the transformers backend on it)."""
    from adaptbench.llm.hf import TransformersBackend
    from adaptbench.llm.named import resolve_model

    path = resolve_model("student")
    return path, TransformersBackend(path, batch_size=16)


@pytest.fixture(scope="module")
def local_rows(student, tmp_path_factory):
    """The local backend's rows on the selection."""
    return build(student[0], tmp_path_factory.mktemp("local") / "data")


def test_served_rows_equal_the_local_backends(student, tmp_path, local_rows):
    from .fake_server import serve

    srv, url = serve(student[1], logprobs="vllm")
    try:
        rows = build(student[0], tmp_path / "served", "--backend", "openai", "--url", url)
    finally:
        srv.shutdown()
    assert {r["kind"] for r in rows} == {"question", "teacher"} and all(r["rejected_token_ids"] for r in rows)
    print(f"\n{len(rows)} rows, {sum(r['p_teacher'] is not None for r in rows)} scored, kinds {sorted({r['kind'] for r in rows})}; "
          f"largest |score difference| served vs local: {same_rows(rows, local_rows, 1e-4):.1e}")
    scored = [r for r in rows if r["p_teacher"] is not None]
    assert {r["score_dtype"] for r in scored} == {"server"}
    gen = [b for b in srv.bodies if not b.get("echo")]
    score = [b for b in srv.bodies if b.get("echo")]
    assert gen and all(isinstance(b["prompt"], list) and b.get("return_token_ids") for b in gen)  # token ids
    assert len(score) == 1 + 3 * len(scored)  # the start-up check, then a^t, a^s after x and a^t after (x, q, answer)
    summary = json.loads((tmp_path / "served" / "summary.json").read_text())
    assert summary["selection"]["backend"] == "openai" and summary["backend"]["url"] == url


def test_a_server_that_cannot_score_is_one_line(tiny, backend, tmp_path, capsys):
    from .fake_server import serve

    srv, url = serve(backend, logprobs="none")
    try:
        code = main(["train", "data", "--student", str(tiny), "--out", str(tmp_path / "d"), *SELECTION,
                     "--backend", "openai", "--url", url, "--model", "tiny"])
    finally:
        srv.shutdown()
    said = [x for x in capsys.readouterr().err.splitlines() if x.strip()]
    assert code == 2 and len(said) == 1 and "no prompt log-probabilities" in said[0], said
    assert not (tmp_path / "d" / "pairs.jsonl").exists()


def test_no_server_is_one_line(tiny, tmp_path, capsys):
    from ..procs import free_port

    url = f"http://127.0.0.1:{free_port()}/v1"
    code = main(["train", "data", "--student", str(tiny), "--out", str(tmp_path / "d"), *SELECTION,
                 "--backend", "openai", "--url", url])
    said = [x for x in capsys.readouterr().err.splitlines() if x.strip()]
    assert code == 2 and len(said) == 1 and said[0].startswith(f"adapt: no answer from {url}"), said
