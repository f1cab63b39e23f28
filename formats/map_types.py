"""The map types every layer shares: the grid geometry and the feature table.

The mapper produces them, the writers write them, evaluation reads them back; they live
here, on the ground floor, so that none of those layers reaches up for them. World (map)
frame of REP 103: metres, radians, yaw counter-clockwise. Grid arrays are indexed
``[row, col]`` with row 0 at the *minimum* y (``origin_y``) — writers flip rows for image
formats whose row 0 is the top.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from formats.arrays import F32, F64, I64

__all__ = ["DEFAULT_MAX_CELLS", "FeatureTable", "GridSpec", "ProbabilityMap"]

#: The largest grid (cells) built or read unless configured otherwise (``[grid] max_cells``;
#: ~32 bytes a cell while mapping keeps a run under ~1.5 GB).
DEFAULT_MAX_CELLS = 40_000_000


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


class ProbabilityMap(Protocol):
    """What a map picture needs: the grid and a float32 occupancy probability per cell
    (NaN = unknown). The mapper's ``MapSnapshot`` is one."""

    @property
    def grid(self) -> GridSpec: ...

    @property
    def probability(self) -> F32: ...
