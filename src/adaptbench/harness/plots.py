"""Plots of evaluation results with matplotlib (the `plots` extra): satisfaction per agent on seen and
unseen personas with standard errors and the questions asked, and a persona x agent heat map.

The file type follows the suffix (`.png`, `.svg`, `.pdf`); without matplotlib, `PlotsUnavailable` says
how to install it.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import AdaptError
from .evaluate import mean_se

INSTALL = "pip install 'adaptbench[plots]'"


class PlotsUnavailable(AdaptError, RuntimeError):
    """matplotlib is not installed."""


def _pyplot():
    try:
        import matplotlib
    except ImportError:
        raise PlotsUnavailable(f"plots need matplotlib: {INSTALL}") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _bars(ax, rows: list) -> None:
    agents = [r["agent"] for r in rows]
    width = 0.38
    for k, (split, color) in enumerate((("seen", "#4c78a8"), ("unseen", "#f58518"))):
        means = [r[f"rate_{split}"][0] for r in rows]
        errs = [r[f"rate_{split}"][1] or 0.0 for r in rows]
        xs = [i + (k - 0.5) * width for i in range(len(rows))]
        ax.bar(xs, [m or 0.0 for m in means], width, yerr=errs, capsize=3, color=color, label=split)
        for x, m, r in zip(xs, means, rows, strict=True):
            q = r[f"questions_{split}"][0]
            label = "n/a" if m is None else f"{m:.0%}\n{q or 0:.1f} q"
            ax.text(x, (m or 0.0) + 0.03, label, ha="center", va="bottom", fontsize=8)
    ax.set_xticks(range(len(rows)), agents)
    ax.set_ylim(0, 1.25)
    ax.set_ylabel("preference satisfaction")
    ax.set_title("Satisfaction per agent (± s.e.; q = questions asked)")
    ax.legend(loc="upper left", fontsize=8)


def persona_matrix(records: list, agents: list) -> tuple[list, list]:
    """(personas, rows of mean satisfaction per agent, None where no preference applied)."""
    personas = sorted({r.persona for r in records})
    grid = []
    for p in personas:
        row = []
        for a in agents:
            rates = [r.satisfaction_rate for r in records
                     if r.persona == p and r.agent == a and r.satisfaction_rate is not None]
            row.append(mean_se(rates)[0])
        grid.append(row)
    return personas, grid


def _heatmap(ax, records: list, agents: list) -> None:
    personas, grid = persona_matrix(records, agents)
    values = [[float("nan") if m is None else m for m in row] for row in grid]
    ax.imshow(values, cmap="Blues", vmin=0, vmax=1, aspect="auto")
    for i, row in enumerate(grid):
        for j, m in enumerate(row):
            text = "n/a" if m is None else f"{m:.0%}"
            ax.text(j, i, text, ha="center", va="center", fontsize=8, color="white" if (m or 0) > 0.6 else "black")
    ax.set_xticks(range(len(agents)), agents)
    ax.set_yticks(range(len(personas)), personas)
    ax.set_title("Satisfaction by persona")


def draw(rows: list, records: list, path: Path) -> None:
    """Write the per-agent bars and the persona heat map to `path` (type from its suffix)."""
    plt = _pyplot()
    agents = [r["agent"] for r in rows]
    n_personas = len({r.persona for r in records})
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(max(6, 1.6 * len(agents) + 3), 4 + 0.32 * n_personas + 2),
                                      gridspec_kw={"height_ratios": [4, max(2, 0.32 * n_personas)]})
    _bars(top, rows)
    _heatmap(bottom, records, agents)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
