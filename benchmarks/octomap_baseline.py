"""The peer: a plain OctoMap grid of the same readings, on the same grid as sonarmap's maps.

Each echo is inserted as it would be by a user of OctoMap (``octomap-python``, default
sensor model: hit 0.7, miss 0.4, clamps 0.12/0.97): one ``insertPointCloud`` per reading,
a fan of rays one cell apart across the cone at the echo's range, from the sonar origin.
Max-range readings are either skipped (as sonarmap's methods do by default) or inserted as
free rays clipped at the sensor's reach (OctoMap's ``maxrange``): two variants. The readings come
through sonarmap's own ingest, pose sync and scan building (:func:`pipeline.run.stream_scans`),
so every method sees exactly the same readings and poses.

The octree's leaves are read back onto the sonarmap grid (z = 0 slice), each cell as
``tree.search`` at its centre reads it (:func:`leaves_on_grid`). Two classifications
are scored: OctoMap's own occupancy threshold (p > 0.5 occupied, other known cells free)
and nav2's trinary thresholds (p > 0.65 occupied, p < 0.196 free) that sonarmap's maps are
scored with; the comparison reports the best of the variants and classifications for
OctoMap (what a user who tried both would keep).
"""

from __future__ import annotations

import contextlib
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


def cone_fan(scan: Scan, k: int, resolution: float, max_range_free: bool = False
             ) -> tuple[F64, float] | None:
    """Reading ``k``'s fan: end points (N, 3) one cell apart across the cone, and the
    ``maxrange`` to insert them with; None for a reading OctoMap is not given.

    An echo's fan lies at its range (hits at the end points). A max-range reading (no echo)
    is skipped, or with ``max_range_free`` its fan lies just beyond the sensor's reach and is
    inserted with ``maxrange`` = that reach, so OctoMap clears the cone up to it and marks
    nothing occupied (OctoMap's own max-range clipping).
    """
    d, r_max = float(scan.range_m[k]), float(scan.max_range[k])
    if math.isfinite(d) and scan.min_range[k] <= d < r_max - 0.01:
        reach, clip = d, r_max
    elif max_range_free and (d == math.inf or (math.isfinite(d) and d >= r_max - 0.01)):
        reach, clip = r_max + resolution, r_max
    else:
        return None
    fov = float(scan.fov[k])
    n = max(2, math.ceil(reach * fov / resolution) + 1)
    ang = scan.alpha[k] + np.linspace(-0.5 * fov, 0.5 * fov, n)
    fan = np.stack(
        [scan.origin_x[k] + reach * np.cos(ang), scan.origin_y[k] + reach * np.sin(ang),
         np.zeros(n)],
        axis=1,
    )
    return fan, clip


def octomap_probability(log: Path, config: Config, max_range_free: bool = False
                        ) -> tuple[F64, GridSpec]:
    """OctoMap's occupancy probability on sonarmap's grid for ``log`` (NaN = unknown);
    ``max_range_free``: max-range readings clear their cone (see :func:`cone_fan`)."""
    tree, grid = octomap_tree(log, config, max_range_free)
    return leaves_on_grid(tree, grid), grid


def octomap_tree(log: Path, config: Config, max_range_free: bool = False
                 ) -> tuple[object, GridSpec]:
    """The OctoMap octree of ``log``'s readings and sonarmap's grid for it."""
    import octomap

    with open_log(log, config) as reader:
        sv, sensors, grid = prepare(reader, config)
        tree = octomap.OcTree(grid.resolution)

        def insert(scans: list[Scan]) -> None:
            for scan in scans:
                for k in range(len(scan)):
                    got = cone_fan(scan, k, grid.resolution, max_range_free)
                    if got is not None:
                        fan, clip = got
                        origin = np.array([scan.origin_x[k], scan.origin_y[k], 0.0])
                        tree.insertPointCloud(fan, origin, maxrange=clip)

        stream_scans(reader, sv, sensors, grid, config, insert)
    return tree, grid


def readback_mismatch(tree: object, grid: GridSpec, prob: F64) -> tuple[int, int]:
    """(cells where ``prob`` differs from ``tree.search`` at the cell centre, known cells)."""
    searched = searched_on_grid(tree, grid)
    known = ~np.isnan(searched)
    differ = (np.isnan(prob) != ~known) | (known & (np.nan_to_num(prob) != np.nan_to_num(searched)))
    return int(differ.sum()), int(known.sum())


def leaves_on_grid(tree: object, grid: GridSpec) -> F64:
    """Each grid cell's occupancy as ``tree.search`` at its centre reads it (NaN unknown).

    OctoMap's voxels lie on the lattice ``k · res`` (key ``k + 2^15``; a coordinate's key is
    ``floor(x / res)``). A leaf reports its centre in float32 (−31.975000381 for −31.975),
    so an edge computed from it lands a cell off; the leaf's lowest voxel index is instead
    rounded from a point inside the leaf, and its cells are the grid columns and rows whose
    centres fall in its voxels, exactly the cells whose ``search`` would return it. Only
    leaves that hold the z = 0 slice (voxel index 0 in z) are read.
    """
    res = float(tree.getResolution())  # type: ignore[attr-defined]
    inv = 1.0 / res
    # The voxel index of every column's and row's centre, as OctoMap's coordToKey takes it.
    col_voxel = np.floor((grid.origin_x + (np.arange(grid.width) + 0.5) * grid.resolution)
                         * inv).astype(np.int64)
    row_voxel = np.floor((grid.origin_y + (np.arange(grid.height) + 0.5) * grid.resolution)
                         * inv).astype(np.int64)
    prob = np.full(grid.shape, np.nan)
    for leaf in tree.begin_leafs():  # type: ignore[attr-defined]
        x, y, z = leaf.getCoordinate()
        n = max(1, round(leaf.getSize() * inv))
        kx, ky, kz = (round(v * inv - 0.5 * n) for v in (x, y, z))  # lowest voxel, exact
        if not kz <= 0 < kz + n:
            continue
        c0, c1 = np.searchsorted(col_voxel, [kx, kx + n])
        r0, r1 = np.searchsorted(row_voxel, [ky, ky + n])
        prob[r0:r1, c0:c1] = leaf.getOccupancy()
    return prob


def searched_on_grid(tree: object, grid: GridSpec) -> F64:
    """The independent read-out: ``tree.search`` at every grid cell centre (slow; checks)."""
    import octomap

    prob = np.full(grid.shape, np.nan)
    res = grid.resolution
    for r in range(grid.height):
        y = grid.origin_y + (r + 0.5) * res
        for c in range(grid.width):
            node = tree.search(np.array([grid.origin_x + (c + 0.5) * res, y, 0.0]))  # type: ignore[attr-defined]
            with contextlib.suppress(octomap.NullPointerException):
                prob[r, c] = node.getOccupancy()
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
# How max-range readings are given to OctoMap: skipped, or as free rays up to the reach.
VARIANTS = {"echoes only": False, "max-range readings as free rays": True}
