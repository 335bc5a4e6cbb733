"""Dependency-free SVG plots of evaluation results: satisfaction per agent (with standard errors and
questions asked) and a persona x agent heat map."""

from __future__ import annotations

from html import escape

from .evaluate import mean_se

W, BAR_H, GAP = 720, 26, 8


def _bars(rows: list, top: int) -> tuple[list, int]:
    out = [f'<text x="10" y="{top}" font-weight="bold">Preference satisfaction (seen personas), ± s.e.</text>']
    y = top + 14
    for r in rows:
        m, se = r["rate_seen"]
        if m is None:
            out.append(f'<text x="10" y="{y + 17}">{escape(r["agent"])}</text>')
            out.append(f'<text x="150" y="{y + 17}">n/a (no applicable preference)</text>')
            y += BAR_H + GAP
            continue
        width = max(0.0, m) * 480
        out.append(f'<text x="10" y="{y + 17}">{escape(r["agent"])}</text>')
        out.append(f'<rect x="150" y="{y}" width="{width:.1f}" height="{BAR_H}" fill="#4c78a8"/>')
        lo, hi = 150 + max(0, m - se) * 480, 150 + min(1, m + se) * 480
        out.append(f'<line x1="{lo:.1f}" y1="{y + BAR_H / 2}" x2="{hi:.1f}" y2="{y + BAR_H / 2}" stroke="black"/>')
        q = r["questions_seen"][0] or 0.0
        out.append(f'<text x="{150 + width + 8:.1f}" y="{y + 17}">{m:.1%} · {q:.1f} questions</text>')
        y += BAR_H + GAP
    return out, y


def _color(rate: float) -> str:
    """White (0%) to blue (100%)."""
    v = max(0.0, min(1.0, rate))
    r, g = int(255 - 179 * v), int(255 - 135 * v)
    return f"rgb({r},{g},{int(255 - 87 * v)})"


def _heatmap(records: list, agents: list, top: int) -> tuple[list, int]:
    personas = sorted({r.persona for r in records})
    out = [f'<text x="10" y="{top}" font-weight="bold">Satisfaction by persona</text>']
    y0 = top + 14
    cell_w = min(120, (W - 160) // max(1, len(agents)))
    for j, a in enumerate(agents):
        out.append(f'<text x="{150 + j * cell_w + 4}" y="{y0 + 12}" font-size="11">{escape(a)}</text>')
    y = y0 + 18
    for p in personas:
        out.append(f'<text x="10" y="{y + 14}" font-size="12">{escape(p)}</text>')
        for j, a in enumerate(agents):
            rates = [r.satisfaction_rate for r in records
                     if r.persona == p and r.agent == a and r.satisfaction_rate is not None]
            m = mean_se(rates)[0]
            x = 150 + j * cell_w
            fill, label = ("#dddddd", "n/a") if m is None else (_color(m), f"{m:.0%}")
            out.append(f'<rect x="{x}" y="{y}" width="{cell_w - 2}" height="18" fill="{fill}"/>')
            out.append(f'<text x="{x + 4}" y="{y + 13}" font-size="11">{label}</text>')
        y += 20
    return out, y


def svg(rows: list, records: list) -> str:
    """An SVG with the per-agent bars and the persona heat map."""
    bars, y = _bars(rows, 24)
    heat, y = _heatmap(records, [r["agent"] for r in rows], y + 28)
    body = "\n".join(bars + heat)
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{y + 16}" font-family="sans-serif" '
            f'font-size="13">\n<rect width="100%" height="100%" fill="white"/>\n{body}\n</svg>\n')
