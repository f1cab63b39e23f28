"""What the reports say, as plain text: human-readable values and the summary of a run.

Both documents (HTML and Markdown) are built from these rows, so they say the same thing.
Everything here is a pure function of the metrics (and the evaluation, when a run has
been scored): no clock, no environment.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from formats.natural_order import natural_key

__all__ = [
    "REASON_LABELS",
    "Summary",
    "comparison_differences",
    "format_duration",
    "format_number",
    "format_stamp",
    "format_value",
    "label",
    "nonzero_drops",
    "summarise",
]

#: Readable names of the drop reasons of metrics.json ``dropped``.
REASON_LABELS = {
    "before_first_pose": "before the first pose",
    "after_last_pose": "after the last pose",
    "in_pose_gap": "in a pose gap",
    "late": "late (behind the reorder window)",
    "stamp_backwards": "stamp going backwards",
    "nan": "NaN range",
    "pos_inf": "+inf range (no echo)",
    "neg_inf": "−inf range",
    "negative": "negative range",
    "below_min": "below the min range",
    "max_range": "at the max range (no echo)",
}

_NS = 1_000_000_000


_UNITS = (("_deg_per_m", " (°/m)"), ("_deg", " (°)"), ("_m2", " (m²)"), ("_m", " (m)"),
          ("_s", " (s)"), ("_ns", ""), ("_mb", " (MiB)"))


def label(key: str) -> str:
    """A metrics key as words, its unit suffix in brackets: ``readings_pose_synced`` →
    ``readings pose synced``, ``tolerance_m`` → ``tolerance (m)``."""
    if key in REASON_LABELS:
        return REASON_LABELS[key]
    if key.endswith("duration_s"):  # shown as a duration ("1 min 45.9 s"): no unit needed
        return key[: -len("_s")].replace("_", " ")
    for suffix, unit in _UNITS:
        if key.endswith(suffix) and len(key) > len(suffix):
            return key[: -len(suffix)].replace("_", " ") + unit
    return key.replace("_", " ")


def format_number(v: float | int, digits: int = 4) -> str:
    """Integers with thousands separators; floats to ``digits`` significant digits."""
    if isinstance(v, bool | np.bool_):
        return "yes" if v else "no"
    if isinstance(v, int | np.integer):
        return f"{int(v):,}"
    f = float(v)
    if not math.isfinite(f):
        return "n/a" if math.isnan(f) else ("+inf" if f > 0 else "−inf")
    if f != 0 and (abs(f) < 1e-3 or abs(f) >= 1e6):
        return f"{f:.{digits - 1}e}"
    return f"{f:.{digits}g}" if abs(f) < 10 ** digits else f"{f:,.0f}"


#: Stamps before 2000-01-01 are a log's own clock (time since start-up), not a date.
_EPOCH_2000_S = 946_684_800


def format_stamp(ns: int) -> str:
    """An int ns stamp as UTC date and time to the millisecond; a stamp before 2000 (a
    log clock counting from start-up, not the wall clock) as seconds on that clock."""
    sec, frac = divmod(int(ns), _NS)
    if sec < _EPOCH_2000_S:
        return f"{sec}.{frac // 1_000_000:03d} s on the log's clock"
    t = dt.datetime.fromtimestamp(sec, tz=dt.UTC)
    return f"{t:%Y-%m-%d %H:%M:%S}.{frac // 1_000_000:03d} UTC"


def format_duration(seconds: float) -> str:
    """``45.9 s``, ``1 min 45.9 s``, ``2 h 03 min 10 s``."""
    s = float(seconds)
    if not math.isfinite(s):
        return "n/a"
    if s < 60:
        return f"{s:.3g} s" if s < 10 else f"{s:.1f} s"
    if s < 3600:
        m, rest = divmod(s, 60)
        return f"{int(m)} min {rest:.1f} s"
    h, rest = divmod(round(s), 3600)
    m, sec = divmod(rest, 60)
    return f"{h} h {m:02d} min {sec:02d} s"


def format_value(key: str, value: Any) -> str:
    """A metric as text, chosen by its key: ``*_ns`` stamps as UTC, ``*duration_s`` as a
    duration, fractions stay numbers, lists joined; ``None`` as "n/a"."""
    if value is None:
        return "n/a"
    if isinstance(value, str):
        return value
    if key.endswith("_ns") and isinstance(value, int | np.integer) and not isinstance(value, bool):
        return format_stamp(int(value))
    if key.endswith("duration_s") and isinstance(value, int | float):
        return format_duration(float(value))
    if isinstance(value, bool | np.bool_):
        return "yes" if value else "no"
    if isinstance(value, int | np.integer):
        return format_number(int(value))
    if isinstance(value, float | np.floating):
        return format_number(float(value))
    if isinstance(value, Sequence):
        return ", ".join(format_value("", v) for v in value)
    if isinstance(value, Mapping):  # an entry of a list (a file of the input)
        return "(" + ", ".join(f"{label(str(k))} {format_value(str(k), v)}"
                               for k, v in value.items()) + ")"
    return str(value)


def nonzero_drops(dropped: Mapping[str, Any]) -> list[tuple[str, int]]:
    """Drop reasons with a non-zero count, most first (ties by name)."""
    items = [(str(k), int(v)) for k, v in dropped.items() if isinstance(v, int) and v > 0]
    return sorted(items, key=lambda kv: (-kv[1], kv[0]))


def _pct(part: float, whole: float) -> str:
    return "n/a" if whole <= 0 else f"{100.0 * part / whole:.1f} %"


@dataclass(frozen=True)
class Summary:
    """The answer first: ``rows`` of (label, text) and the run's ``warnings``."""

    title: str
    rows: list[tuple[str, str]]
    warnings: list[str]


def _quality(evaluation: Mapping[str, Any]) -> str | None:
    f1 = evaluation.get("f1")
    if not isinstance(f1, int | float):
        return None
    parts = [f"F1 {f1:.3f}"]
    extra = [f"{name} {100.0 * v:.1f} %" for name in ("precision", "recall")
             if isinstance(v := evaluation.get(name), int | float)]
    text = parts[0] + (f" ({', '.join(extra)})" if extra else "")
    truth = evaluation.get("truth")
    return f"{text} against {truth}" if truth else text


def _trajectory_error(section: Any) -> str:
    """``evaluate --truth-trajectory``'s answer in a line: ATE (RMSE, after the SE(2)
    alignment) and RPE over its distance; empty when it was not asked."""
    if not isinstance(section, Mapping) or not isinstance(section.get("ate_rmse_m"), int | float):
        return ""
    text = (f"ATE {format_number(float(section['ate_rmse_m']), 3)} m RMSE "
            f"({int(section.get('poses_compared', 0)):,} poses, SE(2)-aligned)")
    rpe, delta = section.get("rpe_trans_rmse_m"), section.get("rpe_delta")
    if isinstance(rpe, int | float) and isinstance(delta, int | float):
        text += (f"; RPE {format_number(float(rpe), 3)} m and "
                 f"{format_number(float(section.get('rpe_rot_rmse_deg', 0.0)), 3)}° RMSE per "
                 f"{format_number(float(delta))} {section.get('rpe_unit', 'm')}")
    return text


def _file_text(f: Mapping[str, Any]) -> str:
    """One file of a recording: ``a.bag (2023-11-14 22:13:20.000 UTC to …, 5,001 messages)``."""
    start, end = f.get("start_ns"), f.get("end_ns")
    span = (f"{format_stamp(start)} to {format_stamp(end)}, "
            if isinstance(start, int) and isinstance(end, int) else "")
    return f"{f.get('name', f.get('path', ''))} ({span}{int(f.get('messages', 0)):,} messages)"


def summarise(metrics: Mapping[str, Any], evaluation: Mapping[str, Any] | None = None) -> Summary:
    """The summary block of a run's metrics (metrics.json without timing)."""
    inp = metrics.get("input", {})
    counts = metrics.get("counts", {})
    run = metrics.get("run", {})
    grid = metrics.get("map", {})
    traj = metrics.get("trajectory", {})
    name = str(inp.get("name") or inp.get("path") or "log")
    rows: list[tuple[str, str]] = []
    fmt = f" ({inp['format']})" if inp.get("format") else ""
    rows.append(("Log", f"{name}{fmt}"))
    files = inp.get("files")
    if isinstance(files, Sequence) and files:  # one recording in several files
        rows.append(("Files", "; ".join(_file_text(f) for f in files if isinstance(f, Mapping))))
    if "duration_s" in inp:
        span = format_duration(float(inp["duration_s"]))
        if isinstance(inp.get("start_ns"), int):
            span += f", from {format_stamp(inp['start_ns'])}"
        rows.append(("Duration", span))
    if run:
        method = str(run.get("method", ""))
        if method == "andersone":
            on = run.get("feature_correction", True)
            method = f"andersone (feature correction {'on' if on else 'off'})"
        rows.append(("Method", method))
    readings = int(counts.get("readings", 0))
    used = int(counts.get("readings_used", 0))
    drops = nonzero_drops(metrics.get("dropped", {}))
    text = f"{used:,} of {readings:,} ({_pct(used, readings)})"
    if drops:
        top = ", ".join(f"{n:,} {label(k)}" for k, n in drops[:3])
        more = f" and {len(drops) - 3} more reasons" if len(drops) > 3 else ""
        text += f"; dropped: {top}{more}"
    rows.append(("Readings used", text))
    paper = metrics.get("paper_metric", {})
    features = int(counts.get("features", paper.get("features", 0)))
    mv = paper.get("mean_feature_variance_m2")
    ftext = f"{features:,}"
    if isinstance(mv, int | float):
        ftext += f"; mean feature variance {format_number(mv, 3)} m² (the paper's metric)"
    rows.append(("Features", ftext))
    if grid:
        rows.append((
            "Mapped area",
            f"{format_number(float(grid.get('mapped_area_m2', 0.0)), 4)} m²: "
            f"{int(grid.get('cells_occupied', 0)):,} occupied and {int(grid.get('cells_free', 0)):,} "
            f"free of {int(grid.get('cells_total', 0)):,} cells at "
            f"{format_number(float(grid.get('resolution_m', 0.0)))} m",
        ))
    if traj:
        frames = traj.get("pose_frames") or []
        frame = f" in frame {frames[0]}" if frames and frames[0] else ""
        rows.append((
            "Trajectory",
            f"{format_number(float(traj.get('path_length_m', 0.0)), 4)} m, "
            f"{int(counts.get('poses', 0)):,} poses{frame}",
        ))
    refined = _refinement(metrics.get("pose_refinement"))
    if refined:
        rows.append(("Pose refinement", refined))
    if evaluation and (q := _quality(evaluation)):
        rows.append(("Quality", q))
    if evaluation and (e := _trajectory_error(evaluation.get("trajectory_error"))):
        rows.append(("Trajectory error", e))
    warnings = [str(w) for w in metrics.get("warnings", [])]
    return Summary(title=name, rows=rows, warnings=warnings)


def _refinement(section: Any) -> str:
    """What pose refinement did, as its summary line says it (without the line's own
    ``pose refinement:`` lead); empty when the run did not refine its poses."""
    if not isinstance(section, Mapping) or not section.get("summary"):
        return ""
    text = str(section["summary"])
    lead = "pose refinement: "
    return text[len(lead):] if text.startswith(lead) else text


def comparison_differences(with_: Mapping[str, Any], without: Mapping[str, Any]) -> list[str]:
    """The differences of a ``--compare-correction`` run, named in sentences."""

    def change(a: float, b: float) -> str:
        return "" if b == 0 else f" ({100.0 * (a - b) / b:+.0f} %)"

    out = []
    pairs = (
        ("features", "features", "{:,}"),
        ("mean_feature_variance_m2", "mean feature variance (m²)", "{:.3g}"),
        ("cells_occupied", "occupied cells", "{:,}"),
    )
    for key, name, spec in pairs:
        a, b = with_.get(key), without.get(key)
        if isinstance(a, int | float) and isinstance(b, int | float):
            out.append(f"{name}: {spec.format(a)} with correction, {spec.format(b)} without"
                       f"{change(float(a), float(b))}")
    deleted, corrected = with_.get("features_deleted"), with_.get("features_corrected")
    if isinstance(deleted, int) and isinstance(corrected, int):
        out.append(f"free space deleted {deleted:,} features and refit {corrected:,} times")
    return out


def sensor_rows(sensors: Sequence[Mapping[str, Any]]) -> list[list[str]]:
    """Per-sensor rows in natural order: name, readings, mapped, mount x/y (m), yaw (deg),
    where the mount came from."""
    rows = []
    for s in sorted(sensors, key=lambda s: natural_key(str(s.get("name", "")))):
        mount = list(s.get("mount") or [math.nan] * 3)
        yaw = math.degrees(mount[2]) if isinstance(mount[2], int | float) else math.nan
        rows.append([
            str(s.get("name", "")),
            format_number(int(s.get("readings", 0))),
            format_number(int(s.get("readings_mapped", 0))),
            format_number(float(mount[0]) if mount[0] is not None else math.nan, 3),
            format_number(float(mount[1]) if mount[1] is not None else math.nan, 3),
            format_number(yaw, 3),
            str(s.get("mount_source", "")),
        ])
    return rows
