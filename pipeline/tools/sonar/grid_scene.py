"""The surfaces a sonar's beam meets in an occupancy grid (``emulate --firing-rate``).

The walls are the grid's cells with probability above 0.5 (the laser map's wall rule).
Rays are sphere-traced: each step advances by the distance from the current cell to the
nearest wall cell (Euclidean distance transform) less the cell's half-diagonal, at least
half a cell, until the ray enters a wall cell or leaves the grid. A wall cell's normal is
the minor principal axis of the wall cells within ``NORMAL_RADIUS_M`` (their second
moments, by correlation with a disc); a cell with fewer than ``MIN_NORMAL_CELLS`` wall
neighbours is a small object that faces the sonar. The critical angle is that of the
building patch the hit lies in, and the multipath leg is traced on from the free cell
before the hit along the mirror direction, as in :mod:`.scan_scene`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from formats.arrays import F32, F64, I64
from formats.map_types import GridSpec
from pipeline.tools.sonar.echo import Fan
from pipeline.tools.sonar.model import SonarPhysics
from pipeline.tools.sonar.surfaces import critical_angles, patch_keys

NORMAL_RADIUS_M = 0.2  # wall cells fitted for a wall cell's normal, m
MIN_NORMAL_CELLS = 3  # fewer wall cells in that disc: an object facing the sonar


def wall_normals(wall: npt.NDArray[np.bool_], resolution: float
                 ) -> tuple[F64, F64, npt.NDArray[np.bool_]]:
    """Per cell: the unit normal (nx, ny; any sign) of the wall cells within
    ``NORMAL_RADIUS_M`` (minor principal axis of their second moments, by correlation with
    a disc; x along columns, y along rows) and whether enough wall cells support it."""
    from scipy.ndimage import correlate

    r = max(1, round(NORMAL_RADIUS_M / resolution))
    dy, dx = np.mgrid[-r:r + 1, -r:r + 1].astype(np.float64)
    disc = (dx * dx + dy * dy <= r * r).astype(np.float64)
    w = wall.astype(np.float64)

    def mom(k: F64) -> F64:
        out: F64 = correlate(w, k * disc, mode="constant", cval=0.0)
        return out

    n = mom(np.ones_like(dx))
    nn = np.maximum(n, 1.0)
    mx, my = mom(dx) / nn, mom(dy) / nn
    sxx = mom(dx * dx) / nn - mx * mx
    sxy = mom(dx * dy) / nn - mx * my
    syy = mom(dy * dy) / nn - my * my
    psi = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)  # along the wall
    return -np.sin(psi), np.cos(psi), n >= MIN_NORMAL_CELLS


@dataclass(frozen=True)
class GridScene:
    """Walls of a grid with their clearance (m) and unit normals (nx, ny; any sign)."""

    grid: GridSpec
    wall: npt.NDArray[np.bool_]
    clearance: F64
    nx: F64
    ny: F64
    supported: npt.NDArray[np.bool_]

    @staticmethod
    def from_probability(probability: F32, grid: GridSpec) -> GridScene:
        """The scene of an occupancy grid (row 0 at the minimum y; NaN unknown)."""
        with np.errstate(invalid="ignore"):
            return GridScene.from_walls(np.asarray(probability > 0.5), grid)

    @staticmethod
    def from_walls(wall: npt.NDArray[np.bool_], grid: GridSpec) -> GridScene:
        """The scene of a wall mask (row 0 at the minimum y)."""
        from scipy.ndimage import distance_transform_edt

        res = grid.resolution
        clearance = (distance_transform_edt(~wall) * res if wall.any()
                     else np.full(wall.shape, np.inf))
        nx, ny, supported = wall_normals(wall, res)
        return GridScene(grid, wall, np.asarray(clearance, np.float64), nx, ny, supported)

    def cell(self, x: F64, y: F64) -> I64:
        """Flat cell index of each point, −1 outside the grid."""
        g = self.grid
        c = np.floor((x - g.origin_x) / g.resolution).astype(np.int64)
        r = np.floor((y - g.origin_y) / g.resolution).astype(np.int64)
        inside = (c >= 0) & (c < g.width) & (r >= 0) & (r < g.height)
        return np.where(inside, r * g.width + c, -1)

    def cast(self, ox: F64, oy: F64, ux: F64, uy: F64, reach: F64) -> tuple[F64, I64]:
        """Distance along each ray to the first wall cell (+inf: none within ``reach``) and
        that cell's flat index (−1: none)."""
        res = self.grid.resolution
        wall = self.wall.reshape(-1)
        clear = self.clearance.reshape(-1)
        slack = res * (0.5 + math.sqrt(0.5))
        n = ox.shape[0]
        t = np.zeros(n)
        hit_t = np.full(n, np.inf)
        hit_c = np.full(n, -1, np.int64)
        live = np.arange(n)
        while live.size:
            c = self.cell(ox[live] + t[live] * ux[live], oy[live] + t[live] * uy[live])
            outside = c < 0
            cc = np.maximum(c, 0)
            hit = ~outside & wall[cc]
            hit_t[live[hit]] = t[live[hit]]
            hit_c[live[hit]] = cc[hit]
            t[live] += np.maximum(clear[cc] - slack, 0.5 * res)
            live = live[~outside & ~hit & (t[live] <= reach[live])]
        return hit_t, hit_c


def grid_nearest(scene: GridScene, ox: F64, oy: F64, alpha: F64, max_range: F64, fov: F64,
                 *, ray_step_rad: float = math.radians(1.0)) -> F64:
    """The ideal sonar in the grid: distance to the nearest wall inside each reading's
    nominal cone ``fov`` (full width, rad), +inf when none within ``max_range``."""
    k = max(2, math.ceil(float(fov.max()) / ray_step_rad) + 1)
    frac = np.linspace(-0.5, 0.5, k)
    theta = (alpha[:, None] + fov[:, None] * frac[None, :]).reshape(-1)
    d, _ = scene.cast(np.repeat(ox, k), np.repeat(oy, k), np.cos(theta), np.sin(theta),
                      np.repeat(max_range, k))
    nearest: F64 = d.reshape(-1, k).min(axis=1)
    return np.where(nearest <= max_range, nearest, np.inf)


def grid_fans(
    scene: GridScene, ox: F64, oy: F64, alpha: F64, max_range: F64, physics: SonarPhysics,
    seed: int, *, ray_step_rad: float = math.radians(1.0),
) -> Fan:
    """The fan of each reading (sonar origin ``ox, oy`` in the grid's frame, axis
    ``alpha``) across its audible beam."""
    half = physics.audible_half_angle()
    k = max(2, math.ceil(2 * half / ray_step_rad) + 1)
    frac = np.linspace(-half, half, k)
    n = ox.shape[0]
    theta = (alpha[:, None] + frac[None, :]).reshape(-1)
    ux, uy = np.cos(theta), np.sin(theta)
    rx, ry = np.repeat(ox, k), np.repeat(oy, k)
    reach = np.repeat(max_range, k)
    d1, cell = scene.cast(rx, ry, ux, uy, reach)
    off = np.broadcast_to(np.abs(frac)[None, :], (n, k)).reshape(-1)
    hit = cell >= 0
    cc = np.maximum(cell, 0)
    nx, ny = scene.nx.reshape(-1)[cc], scene.ny.reshape(-1)[cc]
    sup = scene.supported.reshape(-1)[cc]
    hx, hy = rx + d1 * ux, ry + d1 * uy
    crit1 = critical_angles(patch_keys(np.where(hit, hx, 0.0), np.where(hit, hy, 0.0),
                                       physics.surface_patch_m), physics, seed)
    dot = ux * nx + uy * ny
    cos1 = np.where(hit & sup, np.abs(dot), 1.0)
    d2 = np.full(d1.shape, np.inf)
    cos2 = np.ones(d1.shape)
    crit2 = np.zeros(d1.shape)
    res = scene.grid.resolution
    m = np.nonzero(hit & sup & (cos1 < np.cos(crit1)) & (reach - d1 > res))[0]
    if m.size:
        mx, my = ux[m] - 2 * dot[m] * nx[m], uy[m] - 2 * dot[m] * ny[m]
        back = np.maximum(d1[m] - res, 0.0)  # the free cell before the wall
        sx, sy = rx[m] + back * ux[m], ry[m] + back * uy[m]
        t2, c2 = scene.cast(sx, sy, mx, my, reach[m] - d1[m])
        got = c2 >= 0
        mm = m[got]
        d2[mm] = t2[got]
        c2g = c2[got]
        n2x, n2y = scene.nx.reshape(-1)[c2g], scene.ny.reshape(-1)[c2g]
        cos2[mm] = np.where(scene.supported.reshape(-1)[c2g],
                            np.abs(mx[got] * n2x + my[got] * n2y), 1.0)
        gx, gy = sx[got] + t2[got] * mx[got], sy[got] + t2[got] * my[got]
        crit2[mm] = critical_angles(patch_keys(gx, gy, physics.surface_patch_m), physics, seed)
    shape = (n, k)
    return Fan(off.reshape(shape), np.where(hit, d1, np.inf).reshape(shape),
               cos1.reshape(shape), crit1.reshape(shape), d2.reshape(shape),
               cos2.reshape(shape), crit2.reshape(shape))
