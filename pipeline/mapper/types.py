"""The mapper's inputs and outputs: a scan in, a snapshot of the map out.

All geometry is in the world (map) frame of REP 103: metres, radians, yaw counter-clockwise.
Grid arrays are indexed ``[row, col]`` with row 0 at the *minimum* y (``origin_y``) —
writers flip rows for image formats whose row 0 is the top.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]
F32 = npt.NDArray[np.float32]
I64 = npt.NDArray[np.int64]
I32 = npt.NDArray[np.int32]
B = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class GridSpec:
    """Geometry of the map grid: cell (row r, col c) covers
    ``[origin_x + c·res, origin_x + (c+1)·res) × [origin_y + r·res, origin_y + (r+1)·res)``."""

    origin_x: float
    origin_y: float
    resolution: float
    width: int  # columns (x)
    height: int  # rows (y)

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height, self.width)

    @staticmethod
    def covering(xmin: float, ymin: float, xmax: float, ymax: float, resolution: float) -> GridSpec:
        """The smallest grid aligned to ``resolution`` that covers the given box."""
        # Rounded so origins print cleanly in map.yaml (-4.6, not -4.6000000000000005).
        ox = round(float(np.floor(xmin / resolution) * resolution), 9)
        oy = round(float(np.floor(ymin / resolution) * resolution), 9)
        w = int(np.ceil((xmax - ox) / resolution - 1e-9))
        h = int(np.ceil((ymax - oy) / resolution - 1e-9))
        return GridSpec(float(ox), float(oy), float(resolution), max(w, 1), max(h, 1))


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
class FeatureTable:
    """The feature set as columns, one row per feature, in a deterministic order (by id)."""

    id: I64
    x: F64
    y: F64
    cov_xx: F64
    cov_xy: F64
    cov_yy: F64
    measured_times: I64
    first_seen_ns: I64
    last_seen_ns: I64
    merges: I64

    def __len__(self) -> int:
        return int(self.id.shape[0])


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
