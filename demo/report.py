"""A self-contained HTML report with inline SVG plots (no plotting library, no network).

:func:`line_plot`, :func:`histogram` and :func:`top_view` return ``<svg>`` strings;
:func:`html_page` puts sections of them, tables and an optional video together.
"""

from __future__ import annotations

import html

import numpy as np

PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#17becf", "#7f7f7f")
W, H, PAD = 560, 240, 44


def _scale(lo, hi, a, b):
    span = (hi - lo) or 1.0
    return lambda v: a + (np.asarray(v, float) - lo) / span * (b - a)


def _ticks(lo, hi, n=5):
    if not np.isfinite(lo) or not np.isfinite(hi) or hi <= lo:
        return [lo]
    step = 10 ** np.floor(np.log10((hi - lo) / n))
    for m in (1, 2, 5, 10):
        if (hi - lo) / (step * m) <= n:
            step *= m
            break
    return list(np.arange(np.ceil(lo / step) * step, hi + step * 0.5, step))


def _axes(xlo, xhi, ylo, yhi, xlabel, ylabel, title):
    sx, sy = _scale(xlo, xhi, PAD, W - 10), _scale(ylo, yhi, H - 30, 24)
    out = [f'<text x="{W / 2}" y="15" text-anchor="middle" font-weight="bold">{html.escape(title)}</text>',
           f'<line x1="{PAD}" y1="{H - 30}" x2="{W - 10}" y2="{H - 30}" stroke="#444"/>',
           f'<line x1="{PAD}" y1="24" x2="{PAD}" y2="{H - 30}" stroke="#444"/>',
           f'<text x="{W / 2}" y="{H - 4}" text-anchor="middle">{html.escape(xlabel)}</text>',
           f'<text x="11" y="{H / 2}" text-anchor="middle" transform="rotate(-90 11 {H / 2})">{html.escape(ylabel)}</text>']
    for v in _ticks(xlo, xhi):
        out.append(f'<text x="{sx(v):.1f}" y="{H - 17}" text-anchor="middle" font-size="10">{v:g}</text>')
    for v in _ticks(ylo, yhi):
        out.append(f'<text x="{PAD - 4}" y="{sy(v) + 3:.1f}" text-anchor="end" font-size="10">{v:.3g}</text>'
                   f'<line x1="{PAD}" y1="{sy(v):.1f}" x2="{W - 10}" y2="{sy(v):.1f}" stroke="#eee"/>')
    return sx, sy, out


def _svg(parts):
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif" '
            f'font-size="11">' + "".join(parts) + "</svg>")


def _path(xs, ys):
    pts = [(x, y) for x, y in zip(xs, ys) if np.isfinite(x) and np.isfinite(y)]
    return " ".join(f"{'M' if i == 0 else 'L'}{x:.1f},{y:.1f}" for i, (x, y) in enumerate(pts))


def line_plot(x, series: dict, title: str, xlabel: str, ylabel: str, dashed=()) -> str:
    """``series`` name -> y values over ``x``; names in ``dashed`` are drawn dashed."""
    x = np.asarray(x, float)
    ys = [np.asarray(v, float) for v in series.values()]
    finite = np.concatenate([y[np.isfinite(y)] for y in ys]) if ys else np.zeros(1)
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    margin = 0.05 * (hi - lo or 1.0)
    sx, sy, parts = _axes(float(x.min()), float(x.max()), lo - margin, hi + margin, xlabel, ylabel, title)
    for i, (name, y) in enumerate(series.items()):
        c = PALETTE[i % len(PALETTE)]
        dash = ' stroke-dasharray="4 3"' if name in dashed else ""
        parts.append(f'<path d="{_path(sx(x), sy(y))}" fill="none" stroke="{c}" stroke-width="1.4"{dash}/>')
        parts.append(f'<text x="{W - 14}" y="{34 + 13 * i}" text-anchor="end" fill="{c}">{html.escape(name)}</text>')
    return _svg(parts)


def histogram(values, title: str, xlabel: str, bins: int = 30) -> str:
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    counts, edges = np.histogram(v, bins=bins)
    sx, sy, parts = _axes(float(edges[0]), float(edges[-1]), 0.0, float(max(counts.max(), 1)), xlabel, "count", title)
    for c, a, b in zip(counts, edges[:-1], edges[1:]):
        parts.append(f'<rect x="{sx(a):.1f}" y="{sy(c):.1f}" width="{max(sx(b) - sx(a) - 1, 0.5):.1f}" '
                     f'height="{sy(0) - sy(c):.1f}" fill="{PALETTE[0]}"/>')
    return _svg(parts)


def top_view(points, planes, title: str) -> str:
    """Markers ``(N, 3)`` and mirror planes ``[(normal, d)]`` seen from above (x across, z depth),
    with the camera at the origin."""
    P = np.asarray(points, float)
    P = P[np.all(np.isfinite(P), axis=1)]
    xlo, xhi = min(P[:, 0].min(), -10) - 150, max(P[:, 0].max(), 10) + 150
    zlo, zhi = 0.0, P[:, 2].max() + 100
    sx, sz, parts = _axes(xlo, xhi, zlo, zhi, "x (camera frame)", "z (depth)", title)
    for p in P:
        parts.append(f'<circle cx="{sx(p[0]):.1f}" cy="{sz(p[2]):.1f}" r="1.5" fill="{PALETTE[0]}"/>')
    for k, (n, d) in enumerate(planes):
        n = np.asarray(n, float)
        foot = n * d
        along = np.array([-n[2], 0.0, n[0]])
        along /= np.linalg.norm(along) or 1.0
        centre = foot + along * ((P.mean(0) - foot) @ along)
        a, b = centre - along * 200, centre + along * 200
        parts.append(f'<line x1="{sx(a[0]):.1f}" y1="{sz(a[2]):.1f}" x2="{sx(b[0]):.1f}" y2="{sz(b[2]):.1f}" '
                     f'stroke="{PALETTE[1 + k]}" stroke-width="2.5"/>')
        parts.append(f'<text x="{sx(b[0]):.1f}" y="{sz(b[2]) - 4:.1f}" fill="{PALETTE[1 + k]}">mirror {k}</text>')
    parts.append(f'<polygon points="{sx(0):.1f},{sz(0) - 2:.1f} {sx(-12):.1f},{sz(0) - 14:.1f} '
                 f'{sx(12):.1f},{sz(0) - 14:.1f}" fill="#333"/>')
    return _svg(parts)


def table(rows, header=None) -> str:
    out = ["<table>"]
    if header:
        out.append("<tr>" + "".join(f"<th>{html.escape(str(h))}</th>" for h in header) + "</tr>")
    for r in rows:
        out.append("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>")
    return "".join(out) + "</table>"


def html_page(title: str, sections, video: str | None = None) -> str:
    """``sections``: ``(heading, html)`` pairs."""
    body = [f"<h1>{html.escape(title)}</h1>"]
    if video:
        body.append(f'<video src="{html.escape(video)}" controls loop muted width="640"></video>')
    for heading, content in sections:
        body.append(f"<h2>{html.escape(heading)}</h2>{content}")
    style = ("body{font-family:sans-serif;max-width:1180px;margin:2em auto;color:#222}"
             "table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:3px 8px;"
             "text-align:left}svg{margin:4px;border:1px solid #eee}")
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{style}</style></head><body>{''.join(body)}</body></html>\n")
