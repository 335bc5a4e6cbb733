"""`adapt eval` on bad input: counts what it skips and why, refuses mixed specs, quotes its CSV, never
prints nan; `--by` breakdowns."""

from __future__ import annotations

import csv
import json

import pytest

from adaptbench.cli import main


def _rec(persona="juan", task="eggs", seed=0, agent="oracle", rate=1.0, spec="aaa", **kw) -> dict:
    prefs = [{"id": "p1", "verdict": "satisfied" if rate else "inapplicable"},
             {"id": "p2", "verdict": "violated" if isinstance(rate, float) and rate < 1 else "inapplicable"}]
    return {"agent": agent, "persona": persona, "task": task, "seed": seed, "spec_hash": spec,
            "satisfaction_rate": rate, "questions": 2, "preferences": prefs, **kw}


def _write(path, lines) -> str:
    path.write_bytes(b"".join((json.dumps(x).encode() if isinstance(x, dict) else x) + b"\n" for x in lines))
    return str(path)


def test_eval_counts_what_it_skips(tmp_path, capsys):
    f = _write(tmp_path / "a.jsonl", [_rec(), _rec(), b'{"agent": "or', b"\xff\xfe", b"[1, 2]", b"",
                                       _rec(seed=1, rate="high"), _rec(seed=2, error="X: y", traceback="..."),
                                       _rec(seed=3, split=9)])
    assert main(["eval", f]) == 0
    err = capsys.readouterr().err
    for reason in ("1 duplicate episode", "2 not JSON", "1 not UTF-8", "1 not an episode record",
                   "1 bad satisfaction_rate", "1 episode ended in an error", "1 unknown split"):
        assert reason in err, err


def test_eval_never_prints_nan(tmp_path, capsys):
    f = _write(tmp_path / "a.jsonl", [_rec(rate=None), _rec(seed=1, rate=None, split=0)])
    csv_path = tmp_path / "t.csv"
    assert main(["eval", f, "--csv", str(csv_path), "--plot", str(tmp_path / "p.svg")]) == 0
    out = capsys.readouterr().out
    assert "nan" not in out.lower() and "n/a" in out and "no applicable preference" in out
    assert "nan" not in csv_path.read_text().lower() and "nan" not in (tmp_path / "p.svg").read_text()


def test_eval_csv_is_quoted(tmp_path):
    f = _write(tmp_path / "a.jsonl", [_rec(agent='my, "odd" agent')])
    out = tmp_path / "t.csv"
    assert main(["eval", f, "--csv", str(out)]) == 0
    rows = list(csv.reader(out.open()))
    odd = next(r for r in rows if r[0] == "Other methods")
    assert odd[2] == 'my, "odd" agent' and all(len(r) == len(rows[0]) for r in rows)


def test_eval_refuses_mixed_specs(tmp_path, capsys):
    a = _write(tmp_path / "a.jsonl", [_rec(spec="aaa")])
    b = _write(tmp_path / "b.jsonl", [_rec(seed=1, spec="bbb")])
    assert main(["eval", a, b]) == 1
    err = capsys.readouterr().err
    assert "a.jsonl: spec aaa" in err and "b.jsonl: spec bbb" in err and "--allow-mixed" in err
    assert main(["eval", a, b, "--allow-mixed"]) == 0


@pytest.mark.parametrize("args, code, what", [(["missing.jsonl"], 2, "no such file"), (["."], 2, "is a directory")])
def test_eval_bad_paths(args, code, what, capsys):
    assert main(["eval", *args]) == code
    assert what in capsys.readouterr().err


def test_eval_empty_file(tmp_path, capsys):
    f = tmp_path / "e.jsonl"
    f.write_text("")
    assert main(["eval", str(f)]) == 1
    assert "no usable episode records" in capsys.readouterr().err


@pytest.mark.parametrize("by", ["task", "persona", "preference"])
def test_eval_by(tmp_path, capsys, by):
    f = _write(tmp_path / "a.jsonl", [_rec(), _rec(task="cereal", rate=0.5), _rec(persona="ron", rate=None)])
    md = tmp_path / "t.md"
    assert main(["eval", f, "--by", by, "--markdown", str(md), "--csv", str(tmp_path / "t.csv")]) == 0
    out = capsys.readouterr().out
    assert "nan" not in out and "null" not in out and "None" not in out
    if by == "task":
        assert "cereal" in out and "50.0%" in out
    if by == "persona":
        row = next(line for line in out.splitlines() if "ron" in line)
        assert "n/a" in row and row.rstrip().endswith("1")
    if by == "preference":
        assert "ron.p1" in out and "never applicable" in out and "juan.p2" in out
    assert md.read_text().startswith("| Method |")
