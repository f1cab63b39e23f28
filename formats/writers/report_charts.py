"""The report's charts as inline SVG: labelled axes with round ticks, nothing external."""

from __future__ import annotations

import html
import math
from collections.abc import Sequence

import numpy as np

from formats.arrays import F64, I64
from formats.map_types import FeatureTable
from formats.writers.ellipse import covariance_axes
from formats.writers.report_text import format_number

__all__ = ["HIST_BINS", "nice_ticks", "sigma_histogram", "svg_hbars", "svg_histogram"]

HIST_BINS = 20
_AXIS = "#444"
_GRID = "#ddd"


def nice_ticks(lo: float, hi: float, target: int = 5) -> list[float]:
    """Round tick values (1, 2 or 5 × 10^k steps) covering ``[lo, hi]``, about ``target``."""
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return [lo]
    raw = (hi - lo) / max(target - 1, 1)
    exp = math.floor(math.log10(raw))
    step = next(m * 10.0**exp for m in (1.0, 2.0, 5.0, 10.0) if m * 10.0**exp >= raw)
    first = math.ceil(lo / step - 1e-9) * step
    ticks = []
    v = first
    while v <= hi + step * 1e-9:
        ticks.append(round(v, 12))
        v += step
    return ticks


def sigma_histogram(features: FeatureTable) -> tuple[F64, I64]:
    """``(edges (m), counts)`` of the features' σ_major; empty arrays when no features."""
    major, _minor, _theta = covariance_axes(features.cov_xx, features.cov_xy, features.cov_yy)
    major = major[np.isfinite(major)]
    if major.size == 0:
        return np.zeros(0), np.zeros(0, dtype=np.int64)
    lo, hi = float(major.min()), float(major.max())
    if hi - lo < 1e-9:  # all equal: a small window around the value keeps bins non-empty
        lo, hi = max(lo - 5e-4, 0.0), hi + 5e-4
    counts, edges = np.histogram(major, bins=HIST_BINS, range=(lo, hi))
    return edges, counts.astype(np.int64)


def _text(x: float, y: float, s: str, anchor: str = "middle", extra: str = "") -> str:
    return (f'<text x="{x:.1f}" y="{y:.1f}" text-anchor="{anchor}"{extra}>'
            f"{html.escape(s)}</text>")


def svg_histogram(edges: F64, counts: I64, xlabel: str, ylabel: str) -> str:
    """Bars over ``edges`` with x ticks in the data's units and y ticks in counts."""
    if counts.size == 0:
        return "<p><em>no features</em></p>"
    w, h, ml, mr, mb, mt = 600, 260, 64, 16, 52, 12
    pw, ph = w - ml - mr, h - mb - mt
    top = max(int(counts.max()), 1)
    y_ticks = [t for t in nice_ticks(0, top, 5) if t == int(t)]
    ymax = max(top, int(y_ticks[-1]))
    lo, hi = float(edges[0]), float(edges[-1])

    def px(v: float) -> float:
        return ml + (v - lo) / (hi - lo) * pw

    def py(c: float) -> float:
        return mt + ph - ph * c / ymax

    parts = [f'<svg width="{w}" height="{h}" viewBox="0 0 {w} {h}" role="img" '
             f'aria-label="{html.escape(ylabel)} by {html.escape(xlabel)}">']
    for t in y_ticks:
        parts.append(f'<line x1="{ml}" y1="{py(t):.1f}" x2="{ml + pw}" y2="{py(t):.1f}" '
                     f'stroke="{_GRID}"/>')
        parts.append(_text(ml - 6, py(t) + 4, format_number(int(t)), "end"))
    bar_w = pw / counts.size
    for i, c in enumerate(counts.tolist()):
        x = ml + i * bar_w
        parts.append(
            f'<rect x="{x:.1f}" y="{py(c):.1f}" width="{max(bar_w - 1, 1):.1f}" '
            f'height="{mt + ph - py(c):.1f}" fill="#0072b2"><title>'
            f"{edges[i]:.4g}–{edges[i + 1]:.4g}: {c}</title></rect>"
        )
    parts.append(f'<line x1="{ml}" y1="{mt + ph}" x2="{ml + pw}" y2="{mt + ph}" stroke="{_AXIS}"/>')
    parts.append(f'<line x1="{ml}" y1="{mt}" x2="{ml}" y2="{mt + ph}" stroke="{_AXIS}"/>')
    for t in nice_ticks(lo, hi, 6):
        if lo - 1e-12 <= t <= hi + 1e-12:
            parts.append(f'<line x1="{px(t):.1f}" y1="{mt + ph}" x2="{px(t):.1f}" '
                         f'y2="{mt + ph + 5}" stroke="{_AXIS}"/>')
            parts.append(_text(px(t), mt + ph + 18, f"{t:g}"))
    parts.append(_text(ml + pw / 2, h - 8, xlabel))
    parts.append(_text(16, mt + ph / 2, ylabel, extra=f' transform="rotate(-90 16 {mt + ph / 2:.1f})"'))
    parts.append("</svg>")
    return "".join(parts)


def svg_hbars(items: Sequence[tuple[str, int]], xlabel: str) -> str:
    """Horizontal bars, one per (label, value), in the given order, with a labelled x axis."""
    if not items:
        return "<p><em>none</em></p>"
    row, label_w, bar_w, mt = 22, 240, 300, 6
    top = max(max(v for _k, v in items), 1)
    ticks = [t for t in nice_ticks(0, top, 5) if t == int(t)]
    xmax = max(top, int(ticks[-1]))
    w = label_w + bar_w + 90
    plot_h = row * len(items)
    h = mt + plot_h + 44
    parts = [f'<svg width="{w}" height="{h}" viewBox="0 0 {w} {h}" role="img" '
             f'aria-label="{html.escape(xlabel)}">']
    for t in ticks:
        x = label_w + bar_w * t / xmax
        parts.append(f'<line x1="{x:.1f}" y1="{mt}" x2="{x:.1f}" y2="{mt + plot_h + 5}" '
                     f'stroke="{_GRID}"/>')
        parts.append(_text(x, mt + plot_h + 18, format_number(int(t))))
    for i, (name, value) in enumerate(items):
        y = mt + i * row
        bw = bar_w * value / xmax
        short = name if len(name) <= 34 else name[:33] + "…"
        parts.append(f'<text x="{label_w - 6}" y="{y + 15}" text-anchor="end">'
                     f"<title>{html.escape(name)}</title>{html.escape(short)}</text>")
        parts.append(f'<rect x="{label_w}" y="{y + 3}" width="{bw:.1f}" height="{row - 6}" '
                     f'fill="#e66100"/>')
        parts.append(_text(label_w + bw + 6, y + 15, format_number(value), "start"))
    parts.append(f'<line x1="{label_w}" y1="{mt}" x2="{label_w}" y2="{mt + plot_h}" stroke="{_AXIS}"/>')
    parts.append(_text(label_w + bar_w / 2, h - 6, xlabel))
    parts.append("</svg>")
    return "".join(parts)
