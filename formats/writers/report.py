"""``report.html`` (self-contained) and ``report.md``: a run's answer first, then the detail.

Order: the summary (log, duration, method, readings used of all with the main drop
reasons, features, mapped area, trajectory, what pose refinement did when it ran, quality
and trajectory error when the run was scored, warnings),
the map, the comparison with and without feature correction (when run with
``--compare-correction``: the two maps side by side and the differences named), the
evaluation (when ``sonarmap evaluate`` scored the run: every section its result has, in
its order), the charts (σ_major histogram, readings per sensor, dropped readings by
reason; labelled axes, sensors in natural order, reasons that never happened left out)
and the metrics by section with readable keys, UTC times and durations.

The HTML embeds the maps as base64 PNGs and draws its charts as inline SVG; it references
nothing outside itself. The Markdown says the same with the maps as image links and the
charts as tables. Both depend only on their inputs: the timing of a run (which differs on
every rerun) is not shown; it stays in metrics.json.
"""

from __future__ import annotations

import base64
import html
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from formats.errors import OutputError
from formats.map_types import FeatureTable
from formats.tables import markdown_table
from formats.writers.atomic import atomic_write_text
from formats.writers.report_charts import sigma_histogram, svg_hbars, svg_histogram
from formats.writers.report_text import (
    Summary,
    comparison_differences,
    format_value,
    label,
    nonzero_drops,
    sensor_rows,
    summarise,
)

__all__ = ["COMPARISON_LABELS", "write_reports"]

#: Column titles of metrics.json ``comparison`` entries.
COMPARISON_LABELS = {
    "with_correction": "with feature correction",
    "without_correction": "without feature correction",
}

#: Metrics sections shown in the details, in this order (others follow, by name).
_SECTIONS = ("input", "run", "counts", "paper_metric", "map", "trajectory")
_SKIP_SECTIONS = {"timing", "comparison", "sensors", "dropped", "warnings"}

_CSS = """
body { font-family: sans-serif; margin: 1.5em; color: #222; max-width: 1200px; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: left; vertical-align: top; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
table.summary th { background: #f3f3f3; white-space: nowrap; }
.warnings { background: #fff4e0; border-left: 4px solid #e66100; padding: 0.4em 1em; }
.ok { color: #1a7f37; }
img { max-width: 100%; image-rendering: pixelated; border: 1px solid #ccc; }
.side { display: flex; gap: 1em; flex-wrap: wrap; }
.side figure { flex: 1 1 45%; margin: 0; }
svg text { font-family: sans-serif; font-size: 12px; }
"""

Row = tuple[str, str]


# -- content shared by both documents ----------------------------------------------------


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


def _flat_rows(section: Mapping[str, Any], prefix: str = "") -> list[Row]:
    """A (possibly nested) mapping as (readable key, readable value) rows, in its order."""
    rows: list[Row] = []
    for key, value in section.items():
        name = f"{prefix}{label(str(key))}"
        if isinstance(value, Mapping):
            rows += _flat_rows(value, prefix=f"{name}: ")
        else:
            rows.append((name, format_value(str(key), value)))
    return rows


def _detail_sections(metrics: Mapping[str, Any]) -> list[tuple[str, list[Row]]]:
    """The metrics' sections as tables; a section's one-line ``summary`` (pose
    refinement's) heads its table, before the figures it sums up."""
    names = [s for s in _SECTIONS if s in metrics]
    names += sorted(k for k in metrics if k not in _SECTIONS and k not in _SKIP_SECTIONS
                    and isinstance(metrics[k], Mapping))
    sections = []
    for n in names:
        section = dict(metrics[n])
        lead = {"summary": section.pop("summary")} if "summary" in section else {}
        sections.append((label(n).capitalize(), _flat_rows({**lead, **section})))
    return sections


def _evaluation_parts(
    evaluation: Mapping[str, Any],
) -> tuple[list[Row], list[tuple[str, list[str], list[list[str]]]], list[str]]:
    """Scalars as rows; every nested section as (title, header, rows) — a mapping of
    mappings becomes one table with a column per inner key; ``notes`` as a list."""
    scalars: list[Row] = []
    tables: list[tuple[str, list[str], list[list[str]]]] = []
    notes: list[str] = []
    for key, value in evaluation.items():
        if key == "notes" and isinstance(value, Sequence) and not isinstance(value, str):
            notes = [str(n) for n in value]
        elif isinstance(value, Mapping):
            inner = list(value.values())
            if inner and all(isinstance(v, Mapping) for v in inner):
                cols: list[str] = []
                for v in inner:
                    cols += [str(c) for c in v if str(c) not in cols]
                rows = [[label(str(k)), *(format_value(c, v.get(c)) for c in cols)]
                        for k, v in value.items()]
                tables.append((label(key).capitalize(), ["", *map(label, cols)], rows))
            else:
                tables.append((label(key).capitalize(), ["", "value"],
                               [list(r) for r in _flat_rows(value)]))
        else:
            scalars.append((label(key), format_value(key, value)))
    return scalars, tables, notes


# -- HTML --------------------------------------------------------------------------------


def _html_table(header: Sequence[str] | None, rows: Sequence[Sequence[str]],
                cls: str = "", numeric_from: int = 1) -> str:
    out = [f'<table class="{cls}">' if cls else "<table>"]
    if header is not None:
        out.append("<thead><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header)
                   + "</tr></thead>")
    out.append("<tbody>")
    for r in rows:
        cells = []
        for i, c in enumerate(r):
            if cls == "summary" and i == 0:
                cells.append(f"<th>{html.escape(c)}</th>")
            else:
                num = ' class="num"' if i >= numeric_from and _looks_numeric(c) else ""
                cells.append(f"<td{num}>{html.escape(c)}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</tbody></table>")
    return "".join(out)


def _looks_numeric(text: str) -> bool:
    t = text.replace(",", "").replace("−", "-").replace(" %", "").replace("+", "")
    try:
        float(t)
    except ValueError:
        return False
    return True


def _html_warnings(summary: Summary) -> str:
    if not summary.warnings:
        return '<p class="ok">No warnings.</p>'
    items = "".join(f"<li>{html.escape(w)}</li>" for w in summary.warnings)
    return f'<div class="warnings"><strong>Warnings</strong><ul>{items}</ul></div>'


# -- the documents -----------------------------------------------------------------------


def write_reports(
    out_dir: Path,
    *,
    metrics: Mapping[str, Any],
    features: FeatureTable,
    map_png: Path,
    comparison_pngs: Mapping[str, Path] | None = None,
    evaluation: Mapping[str, Any] | None = None,
    figures: Mapping[str, Path] | None = None,
) -> None:
    """Write ``out_dir/report.html`` and ``out_dir/report.md`` (see the module docstring).

    ``metrics``: a run's metrics.json as a dict (a ``timing`` section is ignored);
    ``features``: its feature table (σ histogram); ``map_png``: the map image;
    ``comparison_pngs``: column label → image of the maps shown side by side (with
    ``metrics["comparison"]``); ``evaluation``: a ``sonarmap evaluate`` result as a dict;
    ``figures``: caption → image shown after the map (the pose refinement's trajectories).
    """
    out_dir = Path(out_dir)
    map_png = Path(map_png)
    summary = summarise(metrics, evaluation)
    title = f"{summary.title} — sonarmap report"
    edges, counts = sigma_histogram(features)
    sensors = sensor_rows(metrics.get("sensors", []))
    per_sensor = [(r[0], int(r[1].replace(",", ""))) for r in sensors]
    drops = nonzero_drops(metrics.get("dropped", {}))
    drops_labelled = [(label(k), n) for k, n in drops]
    comparison = metrics.get("comparison")
    comp_cols: list[str] = []
    comp_rows: list[list[str]] = []
    differences: list[str] = []
    if isinstance(comparison, Mapping) and comparison:
        keys = [k for k in comparison if isinstance(comparison[k], Mapping)]
        comp_cols = [COMPARISON_LABELS.get(k, label(k)) for k in keys]
        names: list[str] = []
        for k in keys:
            names += [n for n in comparison[k] if n not in names]
        comp_rows = [[label(n), *(format_value(n, comparison[k].get(n)) for k in keys)]
                     for n in names]
        if "with_correction" in comparison and "without_correction" in comparison:
            differences = comparison_differences(comparison["with_correction"],
                                                 comparison["without_correction"])
    images = dict(comparison_pngs or {})
    details = _detail_sections(metrics)
    ev = _evaluation_parts(evaluation) if evaluation else None
    hist_rows = [[f"{edges[i]:.4g} – {edges[i + 1]:.4g}", f"{int(c):,}"]
                 for i, c in enumerate(counts)]
    sensor_header = ["sensor", "readings", "mapped", "mount x (m)", "mount y (m)",
                     "mount yaw (°)", "mount from"]
    timing_note = ("Timing (seconds per stage, readings/s, peak memory) is in metrics.json "
                   "and left out here, so that a rerun writes the same report.")

    # ---- HTML
    h: list[str] = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{html.escape(title)}</title>",
        f"<style>{_CSS}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
        "<h2>Summary</h2>",
        _html_table(None, summary.rows, cls="summary"),
        _html_warnings(summary),
        "<h2>Map</h2>",
        f'<img alt="map of {html.escape(summary.title)}" src="{_data_uri(map_png)}">',
    ]
    for cap, img in (figures or {}).items():
        h += [f"<h2>{html.escape(cap)}</h2>",
              f'<img alt="{html.escape(cap)}" src="{_data_uri(Path(img))}">']
    if comp_cols:
        h.append("<h2>With and without feature correction</h2>")
        if images:
            h.append('<div class="side">')
            for cap, img in images.items():
                h.append(f'<figure><img alt="{html.escape(cap)}" src="{_data_uri(Path(img))}">'
                         f"<figcaption>{html.escape(cap)}</figcaption></figure>")
            h.append("</div>")
        if differences:
            h.append("<p>Differences:</p><ul>"
                     + "".join(f"<li>{html.escape(d)}</li>" for d in differences) + "</ul>")
        h.append(_html_table(["", *comp_cols], comp_rows))
    if ev is not None:
        scalars, tables, notes = ev
        h += ["<h2>Evaluation</h2>", _html_table(["", "value"], scalars)]
        for sub, header, rows in tables:
            h += [f"<h3>{html.escape(sub)}</h3>", _html_table(header, rows)]
        if notes:
            h.append("<ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in notes) + "</ul>")
    h += [
        "<h2>Feature uncertainty</h2>",
        f"<p>{len(features):,} features: how many have each σ_major (the standard deviation "
        "along the ellipse's long axis).</p>",
        svg_histogram(edges, counts, "σ_major (m)", "features"),
        "<h2>Readings per sensor</h2>",
        svg_hbars(per_sensor, "readings"),
        "<h2>Dropped readings by reason</h2>",
        svg_hbars(drops_labelled, "readings") if drops else "<p>No reading was dropped.</p>",
        "<h2>Details</h2>",
    ]
    for sec, sec_rows in details:
        h += [f"<h3>{html.escape(sec)}</h3>", _html_table(None, sec_rows)]
    if sensors:
        h += ["<h3>Sensors</h3>", _html_table(sensor_header, sensors)]
    h += [f"<p><em>{html.escape(timing_note)}</em></p>", "</body></html>", ""]

    # ---- Markdown
    m: list[str] = [f"# {title}", "", "## Summary", ""]
    m += markdown_table(["", ""], summary.rows)
    m.append("")
    if summary.warnings:
        m += ["**Warnings**", ""] + [f"- {w}" for w in summary.warnings]
    else:
        m.append("No warnings.")
    m += ["", "## Map", "", f"![map of {summary.title}]({_image_ref(map_png, out_dir)})"]
    for cap, img in (figures or {}).items():
        m += ["", f"## {cap}", "", f"![{cap}]({_image_ref(Path(img), out_dir)})"]
    if comp_cols:
        m += ["", "## With and without feature correction", ""]
        if images:
            m += [" ".join(f"![{cap}]({_image_ref(Path(img), out_dir)})"
                           for cap, img in images.items()), ""]
        if differences:
            m += ["Differences:", ""] + [f"- {d}" for d in differences] + [""]
        m += markdown_table(["", *comp_cols], comp_rows)
    if ev is not None:
        scalars, tables, notes = ev
        m += ["", "## Evaluation", ""]
        m += markdown_table(["", "value"], scalars)
        for sub, header, rows in tables:
            m += ["", f"### {sub}", "", *markdown_table(header, rows)]
        if notes:
            m += [""] + [f"- {n}" for n in notes]
    m += ["", "## Feature uncertainty", "", f"{len(features):,} features by σ_major.", ""]
    m += markdown_table(["σ_major (m)", "features"], hist_rows) if hist_rows else ["_no features_"]
    m += ["", "## Readings per sensor", ""]
    m += (markdown_table(["sensor", "readings"], [[k, f"{v:,}"] for k, v in per_sensor])
          if per_sensor else ["_none_"])
    m += ["", "## Dropped readings by reason", ""]
    m += (markdown_table(["reason", "readings"], [[k, f"{v:,}"] for k, v in drops_labelled])
          if drops else ["No reading was dropped."])
    m += ["", "## Details"]
    for sec, sec_rows in details:
        m += ["", f"### {sec}", "", *markdown_table(["", ""], sec_rows)]
    if sensors:
        m += ["", "### Sensors", "", *markdown_table(sensor_header, sensors)]
    m += ["", f"_{timing_note}_", ""]

    atomic_write_text(out_dir / "report.html", "\n".join(h))
    atomic_write_text(out_dir / "report.md", "\n".join(m))
