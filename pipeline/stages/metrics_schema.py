"""metrics.json, typed: its sections as TypedDicts, in one place.

:class:`~pipeline.stages.metrics.RunMetrics` writes these sections; ``evaluate``, ``regress``,
``batch`` and the reports read a run's file through :func:`read_metrics`, which parses it
and checks it against the declarations below (:func:`metrics_doc`): every declared key
that is present must have its declared type, else a :class:`~formats.errors.FormatError`
names the key (``metrics counts.features is not an integer: 'x'``). Keys are optional
(``total=False``): runs of older versions lack the newer ones, and a reader that needs a
key says so when it is missing (``metrics have no counts.features``). Keys not declared
(``counts`` holds the chosen mapper's own counters) are kept as they are.

JSON has no NaN: a number that was not finite is ``null``, hence ``float | None``.
"""

from __future__ import annotations

import json
import math
import types
import typing
from pathlib import Path
from typing import Any, TypedDict, cast, is_typeddict

from formats.errors import FormatError
from formats.text_file import read_text

__all__ = [
    "Counts",
    "InputFile",
    "InputSection",
    "MapSection",
    "Metrics",
    "PaperMetric",
    "RunSection",
    "SensorRow",
    "TrajectorySection",
    "finite",
    "metrics_doc",
    "read_metrics",
]


class InputFile(TypedDict, total=False):
    """One file of a recording read from several files (``input.files``)."""

    path: str
    name: str
    sha256: str
    start_ns: int | None
    end_ns: int | None
    messages: int


class InputSection(TypedDict, total=False):
    """``input``: what was read."""

    path: str
    name: str
    sha256: str  # of the file, or of the files' (sha256, name) lines
    format: str
    duration_s: float | None
    start_ns: int | None
    end_ns: int | None
    max_range_m: float | None  # the largest finite r_max any reading carried
    bytes_lost: int
    messages_recovered: int | None
    losses: list[str]
    files: list[InputFile]
    duplicates_read_once: int


class RunSection(TypedDict, total=False):
    """``run``: how it was mapped."""

    tool_version: str
    method: str  # a pipeline.methods.Method value
    feature_correction: bool
    config_hash: str
    scan_policy: str
    max_pose_gap_s: float
    median_pose_interval_s: float | None


class Counts(TypedDict, total=False):
    """``counts``: readings, poses, scans and features (plus the mapper's own counters)."""

    readings: int
    readings_pose_synced: int
    readings_used: int
    readings_mapped: int
    readings_stamp_backwards: int
    poses: int
    poses_stamp_backwards: int
    poses_duplicate_stamp: int
    poses_spikes: int
    poses_outliers: int
    scans: int
    features: int


class PaperMetric(TypedDict, total=False):
    """``paper_metric``: the paper's quality measure of the feature map."""

    mean_feature_variance_m2: float | None
    mean_major_axis_variance_m2: float | None
    features: int


class MapSection(TypedDict, total=False):
    """``map``: the grid and its cells by nav2 class."""

    width: int
    height: int
    resolution_m: float
    origin: list[float]
    cells_total: int
    cells_occupied: int
    cells_free: int
    cells_unknown: int
    mapped_area_m2: float


class TrajectorySection(TypedDict, total=False):
    """``trajectory``: the poses the map was built from."""

    path_length_m: float
    pose_frames: list[str]
    start_ns: int
    end_ns: int


class SensorRow(TypedDict, total=False):
    """One entry of ``sensors``."""

    name: str
    readings: int


class Metrics(TypedDict, total=False):
    """A run's metrics.json."""

    input: InputSection
    run: RunSection
    counts: Counts
    dropped: dict[str, int]
    paper_metric: PaperMetric
    map: MapSection
    trajectory: TrajectorySection
    sensors: list[SensorRow]
    comparison: dict[str, Any]
    pose_refinement: dict[str, Any]
    warnings: list[str]
    timing: dict[str, Any]


def read_metrics(path: Path) -> Metrics:
    """A run's metrics.json, checked (:func:`metrics_doc`); InputError if missing,
    FormatError if unreadable or a declared key has the wrong type."""
    text = read_text(path, "metrics file")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as err:
        raise FormatError(f"not valid JSON: {err}", path) from err
    return metrics_doc(doc, path)


def metrics_doc(doc: object, source: Path | None = None) -> Metrics:
    """``doc`` (parsed JSON) as :class:`Metrics`, after checking every declared key that
    is present against its declared type."""
    if not isinstance(doc, dict):
        raise FormatError("metrics is not a JSON object", source)
    _check(doc, Metrics, "", source)
    return cast(Metrics, doc)


def finite(v: float | None) -> float | None:
    """``v`` when it is a finite number, else None (a ``null`` metric)."""
    return float(v) if v is not None and math.isfinite(v) else None


_WHAT = {int: "an integer", float: "a number", str: "a string", bool: "true or false"}


def _check(value: object, tp: Any, key: str, source: Path | None) -> None:
    """Raise FormatError unless ``value`` (JSON) fits the declared type ``tp``."""
    if tp is Any:
        return
    if is_typeddict(tp):
        if not isinstance(value, dict):
            _wrong(key, "an object", value, source)
        hints = typing.get_type_hints(tp)
        for k, v in value.items():
            if k in hints:
                _check(v, hints[k], f"{key}.{k}" if key else k, source)
        return
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return
        (inner,) = [a for a in args if a is not type(None)]
        _check(value, inner, key, source)
        return
    if origin is list:
        if not isinstance(value, list):
            _wrong(key, "an array", value, source)
        (item,) = typing.get_args(tp)
        for i, v in enumerate(value):
            _check(v, item, f"{key}[{i}]", source)
        return
    if origin is dict:
        if not isinstance(value, dict):
            _wrong(key, "an object", value, source)
        _, item = typing.get_args(tp)
        for k, v in value.items():
            _check(v, item, f"{key}.{k}", source)
        return
    ok = (
        isinstance(value, bool) if tp is bool
        else isinstance(value, int | float) and not isinstance(value, bool) if tp is float
        else isinstance(value, tp) and not isinstance(value, bool) if tp is int
        else isinstance(value, tp)
    )
    if not ok:
        _wrong(key, _WHAT.get(tp, tp.__name__), value, source)


def _wrong(key: str, what: str, value: object, source: Path | None) -> typing.NoReturn:
    raise FormatError(f"metrics {key} is not {what}: {value!r}", source)
