"""The peer: a plain OctoMap grid of the same readings, on the same grid as sonarmap's maps.

Each echo is inserted as it would be by a user of OctoMap (``octomap-python``, default
sensor model: hit 0.7, miss 0.4, clamps 0.12/0.97): one ``insertPointCloud`` per reading,
a fan of rays one cell apart across the cone at the echo's range, from the sonar origin
(max-range readings skipped, as sonarmap's methods do by default). The readings come
through sonarmap's own ingest, pose sync and scan building (:func:`pipeline.run.stream_scans`),
so every method sees exactly the same readings and poses.

The octree's leaves are read back onto the sonarmap grid (z = 0 slice). Two classifications
are scored: OctoMap's own occupancy threshold (p > 0.5 occupied, other known cells free)
and nav2's trinary thresholds (p > 0.65 occupied, p < 0.196 free) that sonarmap's maps are
scored with; the comparison reports the better of the two for OctoMap.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from formats import open_log
from formats.arrays import F64
from formats.map_types import GridSpec
from pipeline.config import Config
from pipeline.mapper.types import Scan
from pipeline.run import prepare, stream_scans


def available() -> bool:
    """Whether octomap-python is installed (the ``bench`` extra)."""
    try:
        import octomap  # noqa: F401
    except ImportError:
        return False
    return True


def cone_fan(scan: Scan, k: int, resolution: float) -> F64 | None:
    """The end points (N, 3) of reading ``k``'s fan, or None without an echo."""
    d, r_max = float(scan.range_m[k]), float(scan.max_range[k])
    if not (math.isfinite(d) and scan.min_range[k] <= d < r_max - 0.01):
        return None
    fov = float(scan.fov[k])
    n = max(2, math.ceil(d * fov / resolution) + 1)
    ang = scan.alpha[k] + np.linspace(-0.5 * fov, 0.5 * fov, n)
    return np.stack(
        [scan.origin_x[k] + d * np.cos(ang), scan.origin_y[k] + d * np.sin(ang), np.zeros(n)],
        axis=1,
    )


def octomap_probability(log: Path, config: Config) -> tuple[F64, GridSpec]:
    """OctoMap's occupancy probability on sonarmap's grid for ``log`` (NaN = unknown)."""
    import octomap

    with open_log(log, config) as reader:
        sv, sensors, grid = prepare(reader, config)
        tree = octomap.OcTree(grid.resolution)

        def insert(scans: list[Scan]) -> None:
            for scan in scans:
                for k in range(len(scan)):
                    fan = cone_fan(scan, k, grid.resolution)
                    if fan is not None:
                        origin = np.array([scan.origin_x[k], scan.origin_y[k], 0.0])
                        tree.insertPointCloud(fan, origin, maxrange=float(scan.max_range[k]))

        stream_scans(reader, sv, sensors, grid, config, insert)
    return leaves_on_grid(tree, grid), grid


def leaves_on_grid(tree: object, grid: GridSpec) -> F64:
    """Each leaf's occupancy on the grid cells it covers (leaves may span several cells)."""
    res = grid.resolution
    prob = np.full(grid.shape, np.nan)
    for leaf in tree.begin_leafs():  # type: ignore[attr-defined]
        x, y, _ = leaf.getCoordinate()
        size = leaf.getSize()
        c0 = math.floor((x - size / 2 - grid.origin_x) / res + 1e-6)
        r0 = math.floor((y - size / 2 - grid.origin_y) / res + 1e-6)
        k = max(1, round(size / res))
        rows = slice(max(r0, 0), max(min(r0 + k, grid.height), 0))
        cols = slice(max(c0, 0), max(min(c0 + k, grid.width), 0))
        prob[rows, cols] = leaf.getOccupancy()
    return prob


def classes(prob: F64, occupied_above: float, free_below: float) -> np.ndarray:
    """nav2 loader class codes (see :mod:`pipeline.tools.evaluate`) from a probability grid."""
    from pipeline.tools.evaluate import FREE, OCCUPIED, UNKNOWN

    out = np.full(prob.shape, UNKNOWN, dtype=np.int8)
    known = ~np.isnan(prob)
    with np.errstate(invalid="ignore"):
        out[known & (prob < free_below)] = FREE
        out[known & (prob > occupied_above)] = OCCUPIED
    return out


THRESHOLDS = {"OctoMap (p > 0.5)": (0.5, 0.5 + 1e-12), "OctoMap (nav2 0.65/0.196)": (0.65, 0.196)}
