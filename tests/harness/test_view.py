"""`adapt view`: one self-contained HTML page of the episodes, checked as rendered by headless Chromium."""

from __future__ import annotations

import json
import os

import pytest

from adaptbench.cli import main
from adaptbench.harness.record import EpisodeRecord, StepRecord
from adaptbench.harness.rollout import Job, rollout
from adaptbench.harness.view import read_episodes, render

from ..conftest import SMALL
from . import chromium

HOSTILE = '</script><script>document.title="pwned"</script><img src=x onerror=alert(1)>'


def _model_record() -> EpisodeRecord:
    """A model episode as the harness writes one (token statistics, a completion the grammar rejected),
    with hostile text in every field a page could be fooled by."""
    stats = {"prompt_tokens": 1255, "tokens": 9, "level": "observed", "grammar": "default", "accepted": True,
             "seconds": 0.5415, "mask_seconds": 0.089, "forced_tokens": 5}
    steps = (StepRecord("Look for egg", True, "Found egg_0 in fridge_0", completion="Look for egg", stats=stats,
                        prompt=[{"role": "user", "content": HOSTILE}]),
             StepRecord("Cook " + HOSTILE, False, "Failed: " + HOSTILE, completion=HOSTILE,
                        stats={**stats, "accepted": False}))
    prefs = ({"id": "fried", "text": HOSTILE, "verdict": "violated", "reason": "eggs was not completed",
              "steps": [2]},)
    return EpisodeRecord("planner", "ana", "eggs", 7, "hash", {"agent": "planner", "model": HOSTILE}, "scene-x",
                         steps, 0, 1, prefs, 0.0, 0, ())


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = tmp_path_factory.mktemp("view") / "runs.jsonl"
    jobs = [Job(a, p, "eggs", 0) for a in ("oracle", "always-ask") for p in ("ana", "ben")]
    assert rollout(jobs, out, spec=str(SMALL), progress=False).ran == 4
    error = EpisodeRecord("oracle", "ben", "eggs", 9, "hash", error="RuntimeError: boom",
                          traceback="Traceback (most recent call last):\n  ...")
    with out.open("a") as f:
        f.write(_model_record().to_json() + "\n" + error.to_json() + "\n" + "{torn\n")
    return out


def test_every_value_is_escaped_and_the_page_is_self_contained(runs):
    html = render(read_episodes([runs]))
    assert HOSTILE not in html and "&lt;/script&gt;&lt;script&gt;" in html
    assert html.count("<script>") == 1  # the page's own, inline
    assert "<img" not in html and "&lt;img src=x onerror=alert(1)&gt;" in html
    for fetch in ("http://", "https://", "<link rel=\"stylesheet\"", " src=\""):
        assert fetch not in html


def test_cli_counts_episodes_and_refuses_missing_files(runs, tmp_path, capsys):
    out = tmp_path / "report.html"
    assert main(["view", str(runs), "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "6 episode(s) written" in said and "1 line(s) skipped" in said
    assert main(["view", str(tmp_path / "nope.jsonl"), "--out", str(out)]) == 2
    assert "no such file" in capsys.readouterr().err


# CI (.ci/run) installs Chromium and sets ADAPT_REQUIRE_CHROMIUM=1: there a missing browser fails these tests
needs_chromium = pytest.mark.skipif(chromium.browser() is None and not os.environ.get("ADAPT_REQUIRE_CHROMIUM"),
                                    reason="the `adapt view` page tests need headless Chromium on PATH (Debian/Ubuntu: "
                                           "apt-get install chromium)")


@needs_chromium
def test_chromium_reports_console_errors(tmp_path):
    """The check below is real: a page with a script error is caught."""
    bad = tmp_path / "bad.html"
    bad.write_text("<html><body><script>nosuch();</script></body></html>")
    _, console = chromium.run(bad.as_uri(), "--dump-dom")
    assert any("nosuch is not defined" in line for line in console)


@needs_chromium
def test_page_in_chromium_filters_marks_and_shows_no_console_error(runs, tmp_path):
    out = tmp_path / "report.html"
    assert main(["view", str(runs), "--out", str(out)]) == 0
    records = [json.loads(line) for line in runs.read_text().splitlines() if line.startswith("{\"")]
    asks = [i for i, r in enumerate(records) if r["agent"] == "always-ask"]
    dom, console = chromium.run(out.as_uri() + f"#agent=always-ask&open=e{asks[0]}", "--dump-dom")
    assert console == []
    page = chromium.Elements(dom)
    rows = page.with_class("ep-row")
    assert len(rows) == 6
    shown = [r for r in rows if "hidden" not in r["class"].split()]
    assert {r["data-agent"] for r in shown} == {"always-ask"} and len(shown) == len(asks)
    assert page.text["shown"].strip() == f"{len(asks)} shown"
    assert sum(a == "details" and "open" in attrs for a, attrs in page.tags) == 1
    # questions and replies highlighted, failed steps marked, verdicts with their reasons
    first = records[asks[0]]
    questions = [n for n, s in enumerate(first["steps"], 1) if s["ok"] and s["action"].startswith("Ask ")]
    assert questions
    ids = {a.get("id"): a for _, a in page.tags if a.get("id")}
    for n in questions:
        assert "question" in ids[f"e{asks[0]}-s{n}"]["class"].split()
        assert first["steps"][n - 1]["reply"] in page.text[f"e{asks[0]}-s{n}"]
    model = len(records) - 2
    assert "failed" in ids[f"e{model}-s2"]["class"].split()
    assert "not accepted" in page.text[f"e{model}-s2"] and "prompt tokens 1255" in page.text[f"e{model}-s1"]
    for p in first["preferences"]:
        assert p["reason"] in page.text[f"e{asks[0]}"]
    assert "RuntimeError: boom" in page.text[f"e{len(records) - 1}"]
    assert dom.count("<script") == 1 and "<title>adapt view: " in dom and "pwned" not in dom.split("</title>")[0]


@needs_chromium
def test_screenshot_is_a_png(runs, tmp_path):
    out = tmp_path / "report.html"
    assert main(["view", str(runs), "--out", str(out)]) == 0
    png = tmp_path / "shot.png"
    _, console = chromium.run(out.as_uri() + "#open=e0", f"--screenshot={png}", "--window-size=1000,800")
    assert console == [] and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
