"""`adapt view`: results files as one self-contained HTML page."""

from __future__ import annotations

import sys


def _cmd_view(args) -> int:
    from ..harness.view import ViewError, write_report

    try:
        episodes = write_report(args.runs, args.out)
    except ViewError as exc:
        print(f"adapt: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"adapt: cannot write {args.out} ({exc.strerror})", file=sys.stderr)
        return 1
    skipped = sum(episodes.skipped.values())
    print(f"{len(episodes.records)} episode(s) written to {args.out}"
          + (f"; {skipped} line(s) skipped ({', '.join(episodes.skipped)})" if skipped else ""))
    return 0 if episodes.records else 1


def add_commands(sub) -> None:
    """Register view."""
    p = sub.add_parser("view", help="write rollout files as one HTML page to read episodes in a browser",
                       description="Write one self-contained HTML page (no server, nothing fetched): a table of "
                                   "the episodes, filterable by agent, persona and task, and each episode's steps, "
                                   "questions and replies, model statistics and verdicts with their reasons. "
                                   "Filters can be preset from the address: report.html#agent=planner&task=eggs.")
    p.add_argument("runs", nargs="+", help="JSONL files written by adapt rollout")
    p.add_argument("--out", required=True, help="the HTML file to write, e.g. report.html")
    p.set_defaults(func=_cmd_view)
