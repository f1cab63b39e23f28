"""Builders shared by the mapper tests (imported by name: tests/ is not a package)."""

from __future__ import annotations

from typing import Any

import numpy as np

from formats.map_types import GridSpec
from pipeline.mapper.types import Scan


def build_scan(
    ranges: Any,
    alpha: Any = 0.0,
    ox: Any = 0.0,
    oy: Any = 0.0,
    fov: float = np.radians(30.0),
    min_range: float = 0.1,
    max_range: float = 5.0,
    t_ns: int = 1_000,
) -> Scan:
    """A scan of ``len(ranges)`` readings; scalars broadcast (m, rad, ns)."""
    r = np.atleast_1d(np.asarray(ranges, dtype=np.float64))
    n = r.shape[0]

    def col(v: Any) -> np.ndarray:
        return np.broadcast_to(np.asarray(v, dtype=np.float64), (n,)).copy()

    return Scan(
        t_ns=np.full(n, t_ns, dtype=np.int64),
        sensor_id=np.arange(n, dtype=np.int32),
        range_m=r,
        origin_x=col(ox),
        origin_y=col(oy),
        alpha=col(alpha),
        fov=col(fov),
        min_range=col(min_range),
        max_range=col(max_range),
    )




def cell_centres(grid: GridSpec) -> tuple[np.ndarray, np.ndarray]:
    """x and y of every cell centre, shape grid.shape."""
    xs = grid.origin_x + (np.arange(grid.width) + 0.5) * grid.resolution
    ys = grid.origin_y + (np.arange(grid.height) + 0.5) * grid.resolution
    x, y = np.meshgrid(xs, ys)
    return x, y
