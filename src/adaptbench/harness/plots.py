"""Plots of evaluation results with matplotlib (the `plots` extra): satisfaction per method on seen and
unseen personas with standard errors and the questions asked, and a persona x method heat map (`draw`);
the paper's temporal figure (`draw_temporal`) and questions asked against applicable preferences
(`draw_questions`).

The file type follows the suffix (`.png`, `.svg`, `.pdf`); without matplotlib, `PlotsUnavailable` says
how to install it.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import AdaptError
from .evaluate import _order, mean_se


class PlotsUnavailable(AdaptError, RuntimeError):
    """matplotlib is not installed."""


def _pyplot():
    try:
        import matplotlib
    except ImportError:
        from ..install import install_hint

        raise PlotsUnavailable(f"plots need matplotlib: {install_hint('plots')}") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def require() -> None:
    """PlotsUnavailable (how to install matplotlib) when the plots extra is missing."""
    _pyplot()


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


def _save(fig, plt, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def draw_temporal(curves: dict, path: Path) -> None:
    """The paper's temporal figure (`temporal.py`): for each method (`curves`: method -> [Curve]), the mean
    satisfaction reached at each % of the interaction, counting only the preferences satisfied at the end
    (left: as a satisfaction rate, ending at the method's final rate; right: as a fraction of its final
    score, ending at 1), with a band of ± one standard error."""
    from .temporal import mean_curve

    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, normalised in zip(axes, (False, True), strict=True):
        for method in sorted(curves, key=_order):
            pts = [p for p in mean_curve(curves[method], normalised) if p[1] is not None]
            if not pts:
                continue
            xs = [100 * x for x, *_ in pts]
            ms = [m for _, m, _, _ in pts]
            ses = [se for _, _, se, _ in pts]
            line, = ax.plot(xs, ms, label=f"{method} (n={max(n for *_, n in pts)})")
            ax.fill_between(xs, [m - s for m, s in zip(ms, ses, strict=True)],
                            [m + s for m, s in zip(ms, ses, strict=True)], color=line.get_color(), alpha=0.15)
        ax.set_xlabel("% of the interaction")
        ax.set_xlim(0, 100)
        ax.set_ylim(0, 1.05)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("preference satisfaction rate so far")
    axes[0].set_title("Satisfaction over the interaction")
    axes[1].set_ylabel("fraction of the final score")
    axes[1].set_title("Fraction of the final score reached")
    axes[0].legend(fontsize=8, loc="upper left")
    _save(fig, plt, path)


def questions_by_applicable(records: list) -> dict:
    """method -> [(applicable preferences, mean questions, standard error, episodes)], per number of
    applicable preferences (p+ + p-) in the episode; episodes with none are left out."""
    groups: dict = {}
    for r in records:
        n = _applicable(r)
        if n:
            groups.setdefault(r.agent, {}).setdefault(n, []).append(r.questions)
    return {m: [(n, *mean_se(qs), len(qs)) for n, qs in sorted(g.items())] for m, g in groups.items()}


def _applicable(record) -> int:
    if record.satisfied is not None and record.violated is not None:
        return int(record.satisfied) + int(record.violated)
    return sum(p.get("verdict") != "inapplicable" for p in record.preferences)


def draw_questions(records: list, path: Path) -> None:
    """Questions asked against the number of applicable preferences (the paper's Figure "questions"): per
    method, the mean questions (± standard error) of the episodes with each count, and the identity
    line (one question per applicable preference)."""
    plt = _pyplot()
    data = questions_by_applicable(records)
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    top = 1
    methods = sorted(data, key=_order)
    for i, method in enumerate(methods):
        pts = data[method]
        dodge = 0.08 * (i - (len(methods) - 1) / 2)  # methods with the same numbers stay visible side by side
        ax.errorbar([p[0] + dodge for p in pts], [p[1] for p in pts], yerr=[p[2] for p in pts], marker="o",
                    capsize=3, label=f"{method} ({sum(p[3] for p in pts)} episodes)")
        top = max(top, *(p[0] for p in pts))
    ax.plot([0, top], [0, top], color="grey", linestyle=":", linewidth=1, label="one question per preference")
    ax.set_xlabel("applicable preferences in the episode")
    ax.set_ylabel("questions asked (mean ± s.e.)")
    ax.set_title("Questions asked vs. applicable preferences")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    _save(fig, plt, path)


def draw_curve(curve: dict, path: Path) -> None:
    """A learning curve (`training.curve`): for each model size, the share of dishes completed, the mean
    satisfaction rate (both ± one standard error) on the evaluation episodes and the training loss, against
    training updates."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    for ax, key, label in zip(axes, ("dishes_rate", "satisfaction", "loss"),
                              ("dishes completed", "satisfaction rate", "training loss (since the last point)"),
                              strict=True):
        for size in curve["sizes"]:
            pts = [p for p in size["points"] if p.get(key) is not None]
            if not pts:
                continue
            xs = [p["update"] for p in pts]
            ms = [p[key] for p in pts]
            line, = ax.plot(xs, ms, marker="o", label=f"{size['size']} ({size['parameters'] / 1e6:.1f}M)")
            if key != "loss":
                ses = [p[key.replace("_rate", "") + "_se"] or 0.0 for p in pts]
                ax.fill_between(xs, [m - s for m, s in zip(ms, ses, strict=True)],
                                [m + s for m, s in zip(ms, ses, strict=True)], color=line.get_color(), alpha=0.15)
        ax.set_xlabel("training updates (one oracle episode each)")
        ax.set_ylabel(label)
        if key != "loss":
            ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
    n = curve["sizes"][0]["points"][0]["episodes"] if curve["sizes"] and curve["sizes"][0]["points"] else 0
    axes[0].set_title(f"Dishes completed (split {curve['split']} unseen, {n} episodes)")
    axes[1].set_title("Satisfaction")
    axes[2].set_title("Training loss")
    axes[0].legend(fontsize=8, loc="upper left")
    _save(fig, plt, path)
