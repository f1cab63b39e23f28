"""Which true walls the run's path only ever saw obliquely (``evaluate``'s anatomy).

A smooth wall met beyond its specular cut-off returns no echo, and the beams that cross
it then carry free evidence through it (docs/SONAR_PHYSICS.md). A mapper that weighs a
cell's echoes against its free evidence over the whole log erases a wall when most of
the beams that reach it meet it beyond the cut-off. So a true wall cell is *seen
obliquely* when most of the path's sight lines to it (within the sensor reach, not
blocked by another true wall) meet it more than ``incidence_deg`` off its normal.
The normals are the truth map's own (:func:`pipeline.tools.sonar.grid_scene.wall_normals`,
from its wall cells); a cell without enough wall neighbours (a post) has none and is never
oblique. Sight lines: the path decimated to ``POSE_SPACING_M``, from each pose
``RAYS`` rays traced through the truth walls (its visibility); a cell is visible from a
pose when the ray at its bearing reaches it (within 1.5 cells).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from formats.arrays import F64
from formats.map_types import GridSpec
from pipeline.tools.sonar.grid_scene import GridScene

POSE_SPACING_M = 0.25  # the path is decimated to poses this far apart, m
RAYS = 720  # sight lines per pose (0.5° apart)

Bools = npt.NDArray[np.bool_]


def decimate(poses_xy: F64, spacing: float) -> F64:
    """Poses at least ``spacing`` m from the previous kept one (first kept)."""
    keep = [0]
    last = poses_xy[0]
    for i in range(1, poses_xy.shape[0]):
        if math.hypot(*(poses_xy[i] - last)) >= spacing:
            keep.append(i)
            last = poses_xy[i]
    return poses_xy[keep]


def seen_obliquely(walls: Bools, grid: GridSpec, cells: Bools, poses_xy: F64, reach_m: float,
                   incidence_deg: float) -> Bools:
    """Of the wall cells ``cells`` (a mask on ``grid``), those seen obliquely."""
    from scipy.spatial import cKDTree

    out = np.zeros(walls.shape, bool)
    rr, cc = np.nonzero(cells & walls)
    if rr.size == 0 or poses_xy.shape[0] == 0:
        return out
    scene = GridScene.from_walls(walls, grid)
    res = grid.resolution
    pts = decimate(np.asarray(poses_xy, np.float64), POSE_SPACING_M)
    # Each pose's visibility: RAYS rays traced to the first wall (or the reach).
    ang = np.arange(RAYS) * (2 * math.pi / RAYS)
    ox, oy = np.repeat(pts[:, 0], RAYS), np.repeat(pts[:, 1], RAYS)
    ux, uy = np.tile(np.cos(ang), len(pts)), np.tile(np.sin(ang), len(pts))
    seen, _ = scene.cast(ox, oy, ux, uy, np.full(ox.shape, reach_m))
    seen = seen.reshape(len(pts), RAYS)
    cx = grid.origin_x + (cc + 0.5) * res
    cy = grid.origin_y + (rr + 0.5) * res
    nx, ny = scene.nx[rr, cc], scene.ny[rr, cc]
    supported = scene.supported[rr, cc]
    pairs = cKDTree(np.column_stack([cx, cy])).query_ball_tree(cKDTree(pts), reach_m)
    cell_i = np.repeat(np.arange(rr.size), [len(p) for p in pairs])
    pose_i = np.fromiter((j for p in pairs for j in p), np.int64, cell_i.size)
    dx, dy = cx[cell_i] - pts[pose_i, 0], cy[cell_i] - pts[pose_i, 1]
    d = np.hypot(dx, dy)
    bearing = np.mod(np.arctan2(dy, dx), 2 * math.pi)
    k = np.rint(bearing / (2 * math.pi / RAYS)).astype(np.int64) % RAYS
    visible = (d > 0) & (seen[pose_i, k] >= d - 1.5 * res) & (d <= reach_m)
    cos = np.abs(dx * nx[cell_i] + dy * ny[cell_i]) / np.maximum(d, 1e-9)
    views = np.bincount(cell_i[visible], minlength=rr.size)
    beyond = visible & (cos < math.cos(math.radians(incidence_deg)))
    oblique = supported & (2 * np.bincount(cell_i[beyond], minlength=rr.size) > views)
    out[rr[oblique], cc[oblique]] = True
    return out
