"""`adapt view`: results files as one self-contained HTML page for reading episodes.

    html = render(read_episodes(["runs/x.jsonl"]))     # a str: inline CSS and JS, nothing fetched

The page has a table of every episode (agent, persona, task, seed, satisfaction, questions, failed steps),
filters by agent, persona and task (also preset from the address, `report.html#agent=planner&task=eggs`),
and per episode its steps (questions and replies highlighted, failed steps marked, a model's completion
and token statistics), its verdicts with their reasons and deciding steps, and any error. Every value
from the records is escaped by jinja2's autoescaping; the template ships as package data.
"""

from __future__ import annotations

import json
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from .record import EpisodeRecord, RecordError
from .results import iter_lines, parse_line

# token statistics shown first, in this order, with their labels; any other key follows as it is named
STAT_LABELS = (("prompt_tokens", "prompt tokens"), ("omitted", "steps omitted"), ("tokens", "completion tokens"),
               ("level", "grammar level"), ("grammar", "grammar"), ("accepted", "accepted"), ("tries", "tries"),
               ("seconds", "seconds"), ("prepare_seconds", "prepare s"), ("mask_seconds", "mask s"),
               ("read_seconds", "read s"))


class ViewError(Exception):
    """A results file that cannot be shown (missing, a directory, unreadable); the message says why."""


@dataclass
class Episodes:
    """The episode records of some results files, the lines skipped and why, and the files read."""

    records: list = field(default_factory=list)
    skipped: Counter = field(default_factory=Counter)
    sources: list = field(default_factory=list)


def read_episodes(paths) -> Episodes:
    """Every episode record in the files, those that ended in an error included; ViewError for a file
    that is missing or unreadable."""
    out = Episodes()
    for path in map(Path, paths):
        if not path.is_file():
            raise ViewError(f"no such file: {path}" if not path.exists() else f"{path} is not a results file")
        out.sources.append(str(path))
        try:
            for _, line in iter_lines(path):
                _add(out, *parse_line(line))
        except OSError as exc:
            raise ViewError(f"cannot read {path} ({exc.strerror})") from None
    return out


def _add(out: Episodes, rec, why) -> None:
    if rec is None:
        out.skipped[why] += 1
        return
    try:
        out.records.append(EpisodeRecord.from_dict(rec))
    except RecordError as exc:
        out.skipped[str(exc)] += 1


def _number(value) -> str:
    if isinstance(value, float):
        return f"{value:.3g}" if abs(value) < 1000 else f"{value:.0f}"
    return str(value)


def stat_items(stats: dict | None) -> list:
    """(label, text) pairs of a model step's statistics: the known ones first, then the rest by name."""
    if not stats:
        return []
    known = dict(STAT_LABELS)
    items = [(label, _number(stats[key])) for key, label in STAT_LABELS if key in stats]
    return items + [(key.replace("_", " "), _number(v) if not isinstance(v, dict | list) else json.dumps(v))
                    for key, v in stats.items() if key not in known]


def _prompt_text(prompt) -> str | None:
    """A recorded prompt as text: a string as it is, chat messages as `role: content` blocks."""
    if prompt is None:
        return None
    if isinstance(prompt, str):
        return prompt
    if isinstance(prompt, list) and all(isinstance(m, dict) for m in prompt):
        return "\n\n".join(f"[{m.get('role', '?')}]\n{m.get('content', '')}" for m in prompt)
    return json.dumps(prompt, indent=1)


def _step_view(n: int, step) -> dict:
    stats = step.stats or {}
    return {"n": n, "action": step.action, "ok": step.ok, "observation": step.observation, "reply": step.reply,
            "question": step.action.startswith("Ask "),
            "completion": step.completion if step.completion not in (None, step.action) else None,
            "stats": stat_items(stats), "rejected": stats.get("accepted") is False,
            "prompt": _prompt_text(step.prompt), "targets": list(step.targets or ())}


def _rate(rec) -> str:
    return "n/a" if rec.satisfaction_rate is None else f"{rec.satisfaction_rate:.0%}"


def episode_view(i: int, rec: EpisodeRecord) -> dict:
    """What the template shows of one episode (its anchor is `e<i>`)."""
    steps = [_step_view(n, s) for n, s in enumerate(rec.steps, 1)]
    config = {k: v for k, v in rec.config.items() if k != "agent"}
    return {"id": f"e{i}", "agent": rec.agent, "persona": rec.persona, "task": rec.task, "seed": rec.seed,
            "split": rec.split, "scene": rec.scene, "spec_hash": rec.spec_hash, "config": config,
            "rate": _rate(rec), "rate_value": rec.satisfaction_rate, "satisfied": rec.satisfied,
            "violated": rec.violated, "questions": rec.questions, "steps": steps,
            "failed": sum(not s["ok"] for s in steps), "preferences": list(rec.preferences),
            "completed": list(rec.completed), "notes": list(rec.notes), "error": rec.error,
            "traceback": rec.traceback, "model": any(s["stats"] for s in steps)}


def _template():
    from jinja2 import Environment, PackageLoader, StrictUndefined, select_autoescape

    env = Environment(loader=PackageLoader("adaptbench.harness", "templates"),
                      autoescape=select_autoescape(default=True, default_for_string=True),
                      undefined=StrictUndefined, trim_blocks=True, lstrip_blocks=True)
    return env.get_template("view.html.j2")


def render(episodes: Episodes, title: str | None = None) -> str:
    """The HTML page of the episodes (one string, self-contained)."""
    views = [episode_view(i, r) for i, r in enumerate(episodes.records)]
    choices = {k: sorted({str(v[k]) for v in views}) for k in ("agent", "persona", "task")}
    skipped = ", ".join(f"{n} {why}" for why, n in episodes.skipped.most_common())
    return _template().render(title=title or ", ".join(episodes.sources) or "no files", episodes=views,
                              choices=choices, sources=episodes.sources, skipped=skipped)


def write_report(paths, out) -> Episodes:
    """Render the episodes of `paths` to the HTML file `out` (written whole: a temporary file renamed)."""
    episodes = read_episodes(paths)
    out = Path(out)
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(render(episodes), encoding="utf-8")
    tmp.replace(out)
    return episodes
