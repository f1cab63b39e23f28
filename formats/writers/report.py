"""``report.html`` (self-contained) and ``report.md``: the map, charts and metrics of a run.

The HTML embeds the map as a base64 PNG and draws its charts as inline SVG; it references
nothing outside itself (no CDN, no web fonts, no external images). The Markdown carries the
same content with the map as an image link and the charts as tables. Both are written
atomically and depend only on their inputs (no timestamps).
"""

from __future__ import annotations

import base64
import html
import json
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from formats.errors import OutputError
from formats.map_types import FeatureTable
from formats.tables import markdown_table
from formats.writers.atomic import atomic_write_text
from formats.writers.ellipse import covariance_axes

__all__ = ["flatten_metrics", "format_value", "write_reports"]

HIST_BINS = 20
_IMAGES_KEY = "images"

_CSS = """
body { font-family: sans-serif; margin: 1.5em; color: #222; max-width: 1200px; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: left; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
img { max-width: 100%; image-rendering: pixelated; border: 1px solid #ccc; }
.side { display: flex; gap: 1em; flex-wrap: wrap; }
.side figure { flex: 1 1 45%; margin: 0; }
svg text { font-family: sans-serif; font-size: 12px; }
"""


# -- values ----------------------------------------------------------------------------


def flatten_metrics(metrics: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested dicts as one level with dotted keys, sorted by key (deterministic order)."""
    flat: dict[str, Any] = {}
    for key, value in metrics.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(flatten_metrics(value, prefix=f"{name}."))
        else:
            flat[name] = value
    return dict(sorted(flat.items()))


def format_value(value: Any) -> str:
    """A metric value as text: floats to 6 significant digits, lists as compact JSON."""
    if value is None:
        return "—"
    if isinstance(value, bool | np.bool_):
        return "true" if value else "false"
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        v = float(value)
        return repr(v) if not math.isfinite(v) else f"{v:.6g}"
    if isinstance(value, list | tuple | np.ndarray):
        items = value.tolist() if isinstance(value, np.ndarray) else list(value)
        return json.dumps(items, separators=(",", ":"), default=str)
    return str(value)


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool | np.bool_
    )


# -- charts ----------------------------------------------------------------------------


def _sigma_histogram(features: FeatureTable) -> tuple[np.ndarray, np.ndarray]:
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


def _svg_histogram(edges: np.ndarray, counts: np.ndarray, xlabel: str) -> str:
    if counts.size == 0:
        return "<p><em>no features</em></p>"
    w, h, ml, mb, mt = 560, 220, 48, 40, 10
    pw, ph = w - ml - 10, h - mb - mt
    top = max(int(counts.max()), 1)
    bar_w = pw / counts.size
    parts = [f'<svg width="{w}" height="{h}" viewBox="0 0 {w} {h}" role="img">']
    parts.append(f'<line x1="{ml}" y1="{mt + ph}" x2="{ml + pw}" y2="{mt + ph}" stroke="#444"/>')
    parts.append(f'<line x1="{ml}" y1="{mt}" x2="{ml}" y2="{mt + ph}" stroke="#444"/>')
    for i, c in enumerate(counts.tolist()):
        bh = ph * c / top
        x = ml + i * bar_w
        parts.append(
            f'<rect x="{x:.1f}" y="{mt + ph - bh:.1f}" width="{max(bar_w - 1, 1):.1f}" '
            f'height="{bh:.1f}" fill="#0072b2"><title>{edges[i]:.4g}–{edges[i + 1]:.4g}: '
            f"{c}</title></rect>"
        )
    parts.append(f'<text x="{ml - 4}" y="{mt + 10}" text-anchor="end">{top}</text>')
    parts.append(f'<text x="{ml - 4}" y="{mt + ph}" text-anchor="end">0</text>')
    parts.append(f'<text x="{ml}" y="{h - 22}" text-anchor="middle">{edges[0]:.3g}</text>')
    parts.append(f'<text x="{ml + pw}" y="{h - 22}" text-anchor="end">{edges[-1]:.3g}</text>')
    parts.append(
        f'<text x="{ml + pw / 2:.1f}" y="{h - 6}" text-anchor="middle">{html.escape(xlabel)}</text>'
    )
    parts.append("</svg>")
    return "".join(parts)


def _svg_hbars(items: Sequence[tuple[str, int]], unit: str) -> str:
    if not items:
        return "<p><em>none</em></p>"
    row, label_w, bar_w, w = 22, 240, 260, 600
    h = row * len(items) + 8
    top = max(max(v for _k, v in items), 1)
    parts = [f'<svg width="{w}" height="{h}" viewBox="0 0 {w} {h}" role="img">']
    for i, (label, value) in enumerate(items):
        y = 4 + i * row
        bw = bar_w * value / top
        short = label if len(label) <= 34 else label[:33] + "…"
        parts.append(
            f'<text x="{label_w - 6}" y="{y + 14}" text-anchor="end">'
            f"<title>{html.escape(label)}</title>{html.escape(short)}</text>"
        )
        parts.append(
            f'<rect x="{label_w}" y="{y + 2}" width="{bw:.1f}" height="{row - 6}" fill="#e66100"/>'
        )
        parts.append(
            f'<text x="{label_w + bw + 6:.1f}" y="{y + 14}">{value} {html.escape(unit)}</text>'
        )
    parts.append("</svg>")
    return "".join(parts)


# -- documents -------------------------------------------------------------------------


def _image_ref(image: Path, out_dir: Path) -> str:
    """Path of ``image`` as written in report.md: relative when it lies inside ``out_dir``."""
    try:
        rel = os.path.relpath(image.resolve(), out_dir.resolve())
    except ValueError:  # different drives on Windows
        return image.resolve().as_posix()
    return image.resolve().as_posix() if rel.startswith("..") else Path(rel).as_posix()


def _data_uri(image: Path) -> str:
    try:
        data = image.read_bytes()
    except OSError as err:
        raise OutputError(
            f"cannot read map image for the report: {err.strerror or err}", image
        ) from err
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def _html_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    out = ["<table><thead><tr>"]
    out += [f"<th>{html.escape(h)}</th>" for h in header]
    out.append("</tr></thead><tbody>")
    for r in rows:
        out.append("<tr>")
        for c in r:
            cls = ' class="num"' if _is_number(c) else ""
            out.append(f"<td{cls}>{html.escape(format_value(c))}</td>")
        out.append("</tr>")
    out.append("</tbody></table>")
    return "".join(out)


def _comparison_parts(
    comparison: Mapping[str, Any], out_dir: Path
) -> tuple[list[str], list[list[Any]], list[tuple[str, Path]]]:
    """Column labels, table rows (metric, value per column) and (label, image) pairs."""
    columns = [k for k, v in comparison.items() if k != _IMAGES_KEY and isinstance(v, Mapping)]
    flats = {c: flatten_metrics(comparison[c]) for c in columns}
    keys = sorted(set().union(*(f.keys() for f in flats.values()))) if flats else []
    rows = [[k, *(flats[c].get(k) for c in columns)] for k in keys]
    images_spec = comparison.get(_IMAGES_KEY, {})
    if not isinstance(images_spec, Mapping):
        raise ValueError("comparison['images'] must map a column label to an image file name")
    images = [
        (str(label), Path(name) if Path(name).is_absolute() else out_dir / str(name))
        for label, name in images_spec.items()
    ]
    return columns, rows, images


def write_reports(
    out_dir: Path,
    *,
    metrics: dict[str, Any],
    map_png: Path,
    features: FeatureTable,
    readings_per_sensor: dict[str, int],
    dropped_by_reason: dict[str, int],
    comparison: dict[str, Any] | None = None,
) -> None:
    """Write ``out_dir/report.html`` and ``out_dir/report.md``.

    ``metrics``: nested dict, shown flattened (dotted keys, sorted). ``map_png``: the map
    image (embedded in the HTML, linked from the Markdown). Charts: histogram of feature
    σ_major (m), readings per sensor, dropped readings by reason. ``comparison``: optional
    side-by-side of runs, ``{"with correction": {metrics}, "without correction": {metrics},
    "images": {"with correction": "map.png", "without correction": "map_nocorr.png"}}``
    (image names relative to ``out_dir``), shown as a table with one column per run and
    the images next to each other.
    """
    out_dir = Path(out_dir)
    map_png = Path(map_png)
    flat = flatten_metrics(metrics)
    edges, counts = _sigma_histogram(features)
    sensors = sorted((str(k), int(v)) for k, v in readings_per_sensor.items())
    dropped = sorted((str(k), int(v)) for k, v in dropped_by_reason.items())
    hist_rows = [
        [f"{edges[i]:.4g} – {edges[i + 1]:.4g}", str(int(c))] for i, c in enumerate(counts)
    ]
    comp = _comparison_parts(comparison, out_dir) if comparison is not None else None

    # ---- HTML
    h: list[str] = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        "<title>sonarmap report</title>",
        f"<style>{_CSS}</style></head><body>",
        "<h1>sonarmap report</h1>",
        "<h2>Map</h2>",
        f'<img alt="map" src="{_data_uri(map_png)}">',
    ]
    if comp is not None:
        columns, rows, images = comp
        h.append("<h2>Comparison</h2>")
        if images:
            h.append('<div class="side">')
            for label, img in images:
                h.append(
                    f'<figure><img alt="{html.escape(label)}" src="{_data_uri(img)}">'
                    f"<figcaption>{html.escape(label)}</figcaption></figure>"
                )
            h.append("</div>")
        h.append(_html_table(["metric", *columns], rows))
    h += [
        "<h2>Metrics</h2>",
        _html_table(["metric", "value"], [[k, v] for k, v in flat.items()]),
        "<h2>Feature uncertainty</h2>",
        f"<p>{len(features)} features; histogram of σ_major (m).</p>",
        _svg_histogram(edges, counts, "σ_major (m)"),
        "<h2>Readings per sensor</h2>",
        _svg_hbars(sensors, "readings"),
        "<h2>Dropped readings by reason</h2>",
        _svg_hbars(dropped, "readings"),
        "</body></html>",
        "",
    ]

    # ---- Markdown
    m: list[str] = [
        "# sonarmap report",
        "",
        "## Map",
        "",
        f"![map]({_image_ref(map_png, out_dir)})",
    ]
    if comp is not None:
        columns, rows, images = comp
        m += ["", "## Comparison", ""]
        if images:
            m.append(" ".join(f"![{label}]({_image_ref(img, out_dir)})" for label, img in images))
            m.append("")
        m += markdown_table(["metric", *columns], [[r[0], *map(format_value, r[1:])] for r in rows])
    m += ["", "## Metrics", ""]
    m += markdown_table(["metric", "value"], [[k, format_value(v)] for k, v in flat.items()])
    m += ["", "## Feature uncertainty", "", f"{len(features)} features; σ_major histogram.", ""]
    m += markdown_table(["σ_major (m)", "features"], hist_rows) if hist_rows else ["_no features_"]
    m += ["", "## Readings per sensor", ""]
    m += (
        markdown_table(["sensor", "readings"], [[k, str(v)] for k, v in sensors])
        if sensors
        else ["_none_"]
    )
    m += ["", "## Dropped readings by reason", ""]
    m += (
        markdown_table(["reason", "readings"], [[k, str(v)] for k, v in dropped])
        if dropped
        else ["_none_"]
    )
    m.append("")

    atomic_write_text(out_dir / "report.html", "\n".join(h))
    atomic_write_text(out_dir / "report.md", "\n".join(m))
