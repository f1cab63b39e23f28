"""The mapper's inputs and outputs: a scan in, a snapshot of the map out.

All geometry is in the world (map) frame of REP 103: metres, radians, yaw counter-clockwise.
The grid geometry and the feature table are shared by every layer and defined in
:mod:`formats.map_types`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import overload

from formats.arrays import F32, F64, I32, I64, B
from formats.map_types import FeatureTable, GridSpec

# The mapper's modules take the shared types and array aliases from here too.
__all__ = [
    "F32",
    "F64",
    "I32",
    "I64",
    "SCAN_FIELDS",
    "B",
    "FeatureTable",
    "GridSpec",
    "MapSnapshot",
    "MapperCounters",
    "Scan",
    "ScanBatch",
]


@dataclass(frozen=True)
class Scan:
    """Readings that share one free-space scan (ALGORITHM.md §6), one row per reading.

    The pipeline has already interpolated each reading's robot pose and applied the sensor
    mount: ``origin_x/origin_y`` is the sonar origin ``o`` and ``alpha`` the beam axis angle
    ``α`` in the world frame. Ranges are raw (REP 117: NaN, ±inf, out-of-limit values may be
    present); the mapper classifies and skips them, counting by reason.
    """

    t_ns: I64
    sensor_id: I32
    range_m: F64
    origin_x: F64
    origin_y: F64
    alpha: F64
    fov: F64  # full beam width β, rad
    min_range: F64
    max_range: F64

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    def take(self, rows: slice) -> Scan:
        """The readings ``rows`` as a scan of their own."""
        return Scan(*[getattr(self, name)[rows] for name in SCAN_FIELDS])


# Scan's columns in order (``dataclasses.fields`` costs microseconds a call; scans are many).
SCAN_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(Scan))


class ScanBatch(Sequence[Scan]):
    """Consecutive scans stored as one: ``cat`` holds their readings in order, scan ``k`` is
    rows ``bounds[k]:bounds[k + 1]``. A sequence of scans (views of ``cat``) whose slices
    are batches again, so a group of them is joined without copying
    (:func:`~pipeline.mapper.scan_group.concat_scans`)."""

    def __init__(self, cat: Scan, bounds: Sequence[int]) -> None:
        self.cat = cat
        self.bounds = list(bounds)

    def __len__(self) -> int:
        return len(self.bounds) - 1

    @overload
    def __getitem__(self, index: int) -> Scan: ...

    @overload
    def __getitem__(self, index: slice) -> ScanBatch: ...

    def __getitem__(self, index: int | slice) -> Scan | ScanBatch:
        if isinstance(index, slice):
            lo, hi, step = index.indices(len(self))
            if step != 1:
                raise ValueError("a batch of scans slices with step 1 only")
            hi = max(hi, lo)
            a, b = self.bounds[lo], self.bounds[hi]
            return ScanBatch(self.cat.take(slice(a, b)), [x - a for x in self.bounds[lo:hi + 1]])
        k = range(len(self))[index]
        return self.cat.take(slice(self.bounds[k], self.bounds[k + 1]))


@dataclass
class MapperCounters:
    """Everything that happened inside a mapper, for metrics.json."""

    scans: int = 0
    readings: int = 0
    readings_used: int = 0  # produced a feature (andersone) / an echo update (classic)
    skipped_nan: int = 0
    skipped_pos_inf: int = 0  # REP 117 +inf: nothing detected
    skipped_neg_inf: int = 0  # REP 117 -inf: too close
    skipped_negative: int = 0
    skipped_below_min: int = 0
    skipped_max_range: int = 0  # d >= r_max - eps_max: no echo
    features_created: int = 0
    features_merged: int = 0
    features_corrected: int = 0  # refit from surviving particles
    features_deleted: int = 0
    features_protected: int = 0  # >95 % particles deleted but measured_times >= protect_times
    features_split: int = 0  # split_guard: survivors' mean in a free cell (also deleted/protected)
    cells_freed: int = 0  # sum over scans of the free-space scan's cell count
    echoes_unattributed: int = 0  # attribution: echoes whose whole arc was seen free

    def as_dict(self) -> dict[str, int]:
        return {f.name: int(getattr(self, f.name)) for f in fields(self)}


@dataclass(frozen=True)
class MapSnapshot:
    """The map at one moment.

    ``probability``: float32 occupancy probability per cell, NaN where unknown (eq. 12).
    ``free_logodds``: float32 log-odds of the free layer (0 = never observed).
    ``occupied``: cells inside any feature's 2σ ellipse (andersone) / above 0.5 (classic).
    ``observed``: cells with any evidence.
    """

    grid: GridSpec
    probability: F32
    free_logodds: F32
    occupied: B
    observed: B
    features: FeatureTable
    counters: dict[str, int] = field(default_factory=dict)
