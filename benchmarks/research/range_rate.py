"""The scale error from range rates, with the TRUE map's wall normals (an oracle, issue 17).

A sonar's range to a fixed surface changes with the sensor's motion by the gradient of its
distance: ``Δr = g · Δs`` with ``g = n / cos γ`` (``n`` the surface normal at the hit,
towards the sensor; ``γ`` the angle between ``−n`` and the ray that made the echo, the
cone's edge when the normal lies outside the cone, else 0). Odometry reports ``(1 + k)``
times the true displacement, so over pairs of echoes of one sonar on one surface,
``Δr ≈ g · Δs_odometry / (1 + k)``: a scale estimate that no map score's blur or packing
can bias, *if* the normals are known. This takes them from the truth map (its structure
tensor), so the figure is an upper bound of what range rates can tell on a log; the hit is
the truth map's nearest occupied cell inside the cone within ``HIT_TOLERANCE_M`` of the
range.

Pairs: echoes ``LAG`` readings apart of the same sonar (identified by its mount), the
robot turned ≤ ``MAX_TURN_DEG`` between them, both hits found with normals that agree. The
slope is fitted robustly (Cauchy IRLS) both ways, ``Δr`` on ``g·Δs`` (attenuated by the
normals' noise: leans to ``k > 0``) and ``g·Δs`` on ``Δr`` (attenuated by the ranges'
noise: leans to ``k < 0``), so the two bracket what the data say.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from formats.arrays import F64, I64
from pipeline.refine.echoes import Echoes
from pipeline.refine.surfaces import TENSOR_SIGMA_CELLS, normal_angles
from pipeline.se2 import transform_points

LAG = 10
MAX_TURN_DEG = 2.0
HIT_TOLERANCE_M = 0.15
RAYS = 31


@dataclass(frozen=True)
class RangeRate:
    """The two bracketing scale estimates and how many pairs made them."""

    k_forward: float
    k_reverse: float
    pairs: int


class _Normals:
    """Occupied cells of a map and the unit normal of each cell (structure tensor)."""

    def __init__(self, occupied: np.ndarray, x0: float, y0: float, res: float):
        from scipy.ndimage import gaussian_filter

        self.occ, self.x0, self.y0, self.res = occupied, x0, y0, res
        angle = normal_angles(gaussian_filter(occupied.astype(np.float64), TENSOR_SIGMA_CELLS))
        self.nx, self.ny = np.cos(angle), np.sin(angle)

    def cells(self, x: F64, y: F64) -> tuple[I64, I64, np.ndarray]:
        h, w = self.occ.shape
        with np.errstate(invalid="ignore"):
            c = np.floor((x - self.x0) / self.res)
            r = np.floor((y - self.y0) / self.res)
        ok = (c >= 0) & (c < w) & (r >= 0) & (r < h)
        return np.where(ok, r, 0).astype(np.int64), np.where(ok, c, 0).astype(np.int64), ok

    def gradients(self, sx: F64, sy: F64, axis: F64, half: F64, rng: F64) -> tuple[F64, F64, np.ndarray]:
        """Per echo ``g = n / cos γ`` and whether its hit was found."""
        steps = np.arange(0.0, float(rng.max(initial=0.0)) + 2 * HIT_TOLERANCE_M, self.res / 2)
        best = np.full(sx.shape, np.inf)
        ray = np.zeros(sx.shape)
        u_axis_first = np.linspace(-1.0, 1.0, RAYS)
        # Axis first: of rays tied at the marched distance the one nearest the axis wins
        # (a wall faced squarely is hit along its normal, not at the cone's edge).
        for u in u_axis_first[np.argsort(np.abs(u_axis_first), kind="stable")]:
            ang = axis + half * u
            r, c, ok = self.cells(sx[:, None] + np.cos(ang)[:, None] * steps,
                                  sy[:, None] + np.sin(ang)[:, None] * steps)
            hit = ok & self.occ[r, c]
            first = np.where(hit.any(axis=1), steps[hit.argmax(axis=1)], np.inf)
            ray = np.where(first < best, ang, ray)
            best = np.minimum(first, best)
        found = np.abs(best - rng) <= HIT_TOLERANCE_M
        d = np.where(found, best, 0.0) - self.res / 2  # just before the cell, on the ray
        r, c, ok = self.cells(sx + d * np.cos(ray), sy + d * np.sin(ray))
        nx, ny = self.nx[r, c], self.ny[r, c]
        towards = np.where(nx * np.cos(ray) + ny * np.sin(ray) > 0, -1.0, 1.0)
        nx, ny = nx * towards, ny * towards
        cos_g = -(nx * np.cos(ray) + ny * np.sin(ray))
        found &= ok & (cos_g > 0.3)
        return nx / np.maximum(cos_g, 1e-3), ny / np.maximum(cos_g, 1e-3), found


def _robust_slope(x: F64, y: F64) -> float:
    """``a`` of ``y ≈ a·x`` by iteratively reweighted least squares, Cauchy weights; NaN
    when ``x`` carries no information (all zero)."""
    w = np.ones_like(x)
    a = math.nan
    for _ in range(10):
        sxx = float((w * x * x).sum())
        if not sxx > 1e-12:
            return math.nan
        a = float((w * x * y).sum()) / sxx
        res = y - a * x
        scale = 1.4826 * float(np.median(np.abs(res))) + 1e-6
        w = 1.0 / (1.0 + (res / (2.385 * scale)) ** 2)
    return a


def range_rate_scale(echoes: Echoes, truth_map: Path) -> RangeRate:
    """The range-rate scale estimates of ``echoes`` (odometry poses) against ``truth_map``."""
    from formats.writers.nav2_map import load_nav2_map

    m = load_nav2_map(truth_map)
    normals = _Normals(m.classes == 1, m.grid.origin_x, m.grid.origin_y, m.grid.resolution)
    odo = echoes.odo
    sx, sy = transform_points(odo, echoes.sx, echoes.sy)  # each sonar's position
    gx, gy, found = normals.gradients(sx, sy, odo[:, 2] + echoes.axis, echoes.half,
                                      echoes.range_m)
    sonar = echoes.mounts()
    first, second = [], []
    for k in np.unique(sonar):
        idx = np.flatnonzero(sonar == k)
        first.append(idx[:-LAG])
        second.append(idx[LAG:])
    i, j = np.concatenate(first), np.concatenate(second)
    turn = np.abs((odo[j, 2] - odo[i, 2] + math.pi) % (2 * math.pi) - math.pi)
    keep = ((np.degrees(turn) <= MAX_TURN_DEG) & found[i] & found[j]
            & (gx[i] * gx[j] + gy[i] * gy[j] > 0))
    i, j = i[keep], j[keep]
    if i.size < 2:
        return RangeRate(math.nan, math.nan, int(i.size))
    proj = 0.5 * ((gx[i] + gx[j]) * (sx[j] - sx[i]) + (gy[i] + gy[j]) * (sy[j] - sy[i]))
    dr = echoes.range_m[j] - echoes.range_m[i]
    forward, reverse = _robust_slope(proj, dr), _robust_slope(dr, proj)
    k_forward = 1.0 / forward - 1.0 if forward != 0 else math.nan  # Δr never changed
    return RangeRate(k_forward, reverse - 1.0, int(i.size))
