"""The odometry's scale error from surface patches (``calibration_scale_score =
"surfaces"``, :mod:`pipeline.refine.calibration`).

A sonar's range to a plane is ``r = (n·s − c) / cos γ`` (``s`` the sonar's position, ``n``
the plane's unit normal towards it, ``c`` its offset, ``γ`` the angle between ``−n`` and the
ray that made the echo). Echoes of one plane seen from different distances along its
normal agree on ``c = n·s − r cos γ`` only under the right scale error ``k`` (positions come
from the odometry, ranges do not): no blur, free-space band or packing along a wall enters,
unlike the map scores (the echo consistency leans +3.7 to +5.8 % on true poses). Echoes that
only slide along a wall carry no information and no bias.

One evaluation ``f(k₀)``, from the echoes alone:

Design notes and the measurements behind them: docs/research/pose_refinement.md, "surfaces.py".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from formats.arrays import F64, I64
from pipeline.refine.echoes import Echoes
from pipeline.refine.memo import Memo
from pipeline.refine.scores import Placed, thin
from pipeline.refine.submaps import path_length
from pipeline.refine.threads import parallel_map
from pipeline.se2 import transform_points

# Echoes used (evenly thinned beyond): 16,000 hold ~40 MB of arcs and free-cone samples;
# the logs measured have 1,000-6,500.
MAX_ECHOES = 16_000
CELL_M = 0.1
SIGMA_M = 0.1
ARC_POINTS = 15
FREE_RAY_STRIDE = 7  # free cones sampled on the arc's two edges and its axis
PATCH_M = 0.3
NORMAL_BINS = 16
MIN_PATCH_ECHOES = 3
MIN_TILTED_PATCH_ECHOES = 4  # a patch whose orientation is fitted too keeps 2 residuals
TENSOR_SIGMA_CELLS = 1.5
K0_STEP = 0.02  # the fixed point's k₀ lie on this grid
K0_OFFSETS = (-2, -1, 0, 1, 2)  # ... a window of them about its centre, in steps
K0S = tuple(K0_STEP * j for j in K0_OFFSETS)  # ... the first window: −4 … +4 %
K0_MAX_CENTRE = 2  # ... a window's centre at most ±4 % (the scale applied: at most ±5 %)
STEP = 0.005
# _fit: an echo that moves by less than this per unit of the parameter (m: 10 nm for 1 %
# of scale) does not depend on it; where none does, the parameter is undetermined
UNMOVED_M = 1e-6
WINDOW_M = 30.0
TILT_MIN_SPREAD_M2 = 1e-6  # hits spread along a patch by less (Σ squares, m²): no orientation fitted
CAUCHY = 2.385  # the Cauchy loss's scale in residual σ (95 % efficiency at a Gaussian)
MAD_SIGMA = 1.4826  # σ of a Gaussian per median absolute deviation


def normal_angles(density: F64) -> F64:
    """Per cell, the direction (rad, modulo π) of ``density``'s structure tensor's main
    axis — across a wall, its normal: the outer products of the gradient smoothed over
    :data:`TENSOR_SIGMA_CELLS`. The whole grid: the reference of :func:`normal_angles_at`,
    which the association uses."""
    from scipy.ndimage import gaussian_filter

    gy, gx = np.gradient(density)
    sxx, syy, sxy = (gaussian_filter(v, TENSOR_SIGMA_CELLS) for v in (gx * gx, gy * gy, gx * gy))
    return np.asarray(0.5 * np.arctan2(2 * sxy, sxx - syy))


def normal_angles_at(density: F64, rows: I64, cols: I64) -> F64:
    """``normal_angles(density)[rows, cols]``, bit for bit, with the structure tensor
    filtered at those cells only (compiled: :func:`pipeline.refine.kernels.structure_tensor_at`;
    the whole grid's three filters were two thirds of an association's time)."""
    from pipeline.refine.kernels import gaussian_weights, structure_tensor_at

    gy, gx = (np.asarray(g) for g in np.gradient(density))
    cell, at = np.unique(rows * density.shape[1] + cols, return_inverse=True)  # once each
    t = structure_tensor_at(gx, gy, cell // density.shape[1], cell % density.shape[1],
                            gaussian_weights(TENSOR_SIGMA_CELLS, truncate=4.0))
    return np.asarray(0.5 * np.arctan2(2 * t[:, 2], t[:, 0] - t[:, 1]))[at.ravel()]


Association = tuple[I64, I64, F64, F64, F64]  # Cones.associate's patches


# Surface associations remembered, by (echoes, heading bias, k₀): both patch models
# (calibration_scale_tilt = "fallback") fit the patches of one association, and the
# second model's first fixed point asks for the first's again.
Associations = Memo[tuple[int, float, float], Association]


class Cones:
    """Echoes' whole cones in the base frame (their rays and arc points, computed once) and
    each echo's stretch of travel (``window_m``; 0: one stretch), associated with surface
    patches under any poses of the echoes (:meth:`associate`)."""

    def __init__(self, echoes: Echoes, window_m: float):
        self.echoes = echoes
        self.phi = echoes.arc_angles(1.0, ARC_POINTS)  # the whole cone's rays, base frame
        self.bx, self.by = echoes.arc(1.0, ARC_POINTS)
        # each echo's stretch of travel (odometry, independent of the scale tested)
        travel = path_length(echoes.odo[:, 0], echoes.odo[:, 1])
        self.stretch = (np.floor(travel / window_m) if window_m > 0
                        else np.zeros(len(echoes))).astype(np.int64)

    def associate(self, pose: F64) -> Association:
        """(echo index, patch, patch normal x, y, hit ray angle in the base frame) with the
        echoes at ``pose`` (one row per echo)."""
        from pipeline.refine.kernels import free_samples, gaussian_blur

        e = self.echoes
        if len(e) == 0:
            none = np.empty(0)
            return np.empty(0, np.int64), np.empty(0, np.int64), none, none, none
        wx, wy = transform_points(pose[:, None, :], self.bx, self.by)
        ox, oy = transform_points(pose, e.sx, e.sy)
        steps = np.arange(1, int(e.range_m.max(initial=0.0) / CELL_M) + 1) * CELL_M
        # the free cones: rays on the arc's two edges and its axis, from the sonar to 2σ
        # short of the echo (compiled, without the samples' arrays)
        rx = np.ascontiguousarray(wx[:, ::FREE_RAY_STRIDE])
        ry = np.ascontiguousarray(wy[:, ::FREE_RAY_STRIDE])
        band = 2 * SIGMA_M
        fxmin, fymin, fxmax, fymax = free_samples(ox, oy, rx, ry, e.range_m, steps, band, 0.0,
                                                  0.0, CELL_M, np.zeros((0, 0)))
        x0 = min(float(wx.min()), fxmin) - 1.0
        y0 = min(float(wy.min()), fymin) - 1.0
        w = int((max(float(wx.max()), fxmax) + 1.0 - x0) / CELL_M) + 2
        h = int((max(float(wy.max()), fymax) + 1.0 - y0) / CELL_M) + 2

        def cells(px: F64, py: F64) -> tuple[I64, I64]:
            return (np.clip(((py - y0) / CELL_M).astype(np.int64), 0, h - 1),
                    np.clip(((px - x0) / CELL_M).astype(np.int64), 0, w - 1))

        def density(counts: F64) -> F64:
            return gaussian_blur(counts, SIGMA_M / CELL_M)

        r, c = cells(wx, wy)
        hit = density(np.bincount((r * w + c).ravel(), minlength=h * w).reshape(h, w)
                      .astype(np.float64))
        # each free ray stands for FREE_RAY_STRIDE-odd of the arc's rays
        free = np.zeros((h, w))
        free_samples(ox, oy, rx, ry, e.range_m, steps, band, x0, y0, CELL_M, free)
        fr = density(free) * (wx.shape[1] / rx.shape[1])
        seen = hit[r, c] + fr[r, c]
        ratio = np.where(seen >= 2.0, hit[r, c] / np.maximum(seen, 1e-12), -1.0)
        best = ratio.argmax(axis=1)
        rows = np.arange(len(e))
        px, py = wx[rows, best], wy[rows, best]
        angle = normal_angles_at(hit, *cells(px, py))
        nx, ny = np.cos(angle), np.sin(angle)
        towards = np.where(nx * (ox - px) + ny * (oy - py) < 0, -1.0, 1.0)
        nx, ny = nx * towards, ny * towards
        ray = pose[:, 2] + self.phi[rows, best]
        ok = (ratio[rows, best] >= 0) & (-(nx * np.cos(ray) + ny * np.sin(ray)) > 0.3)
        direction = np.round(np.mod(np.arctan2(ny, nx), 2 * math.pi) / (2 * math.pi / NORMAL_BINS))
        key = np.column_stack([np.floor(px / PATCH_M), np.floor(py / PATCH_M),
                               direction % NORMAL_BINS, self.stretch]).astype(np.int64)
        idx = np.flatnonzero(ok)
        patch = _row_ids(key[idx])
        big = np.bincount(patch)[patch] >= MIN_PATCH_ECHOES
        idx = idx[big]
        _, patch = np.unique(patch[big], return_inverse=True)  # numbered 0 … n − 1
        n = int(patch.max(initial=-1)) + 1
        mx, my = np.bincount(patch, nx[idx], n), np.bincount(patch, ny[idx], n)
        norm = np.maximum(np.hypot(mx, my), 1e-12)
        return idx, patch, (mx / norm)[patch], (my / norm)[patch], self.phi[idx, best[idx]]



class SurfaceScale:
    """``f(k₀)`` of the module docstring for one log's echoes, its fixed point, and the
    same for the heading bias at a given scale. ``associations``: where the patches
    associated under a ``k₀`` are remembered (``echoes`` kept alive meanwhile: its ``id``
    is in the key)."""

    def __init__(self, t_ns: I64, x: F64, y: F64, yaw: F64, echoes: Echoes, bias: float,
                 window_m: float = WINDOW_M, tilt: bool = False,
                 associations: Associations | None = None, recentre: bool = False):
        self.source, self.associations, self.recentre = echoes, associations, recentre
        echoes = echoes.take(thin(len(echoes), MAX_ECHOES))  # memory and time bounded
        self.placed = Placed(t_ns, x, y, yaw, echoes, len(echoes))
        self.cones = Cones(echoes, window_m)
        self.echoes, self.stretch, self.bias, self.tilt = echoes, self.cones.stretch, bias, tilt

    def poses(self, k: float) -> F64:
        return self.placed.poses(k, self.bias * (1.0 + k))

    def _associate(self, pose: F64) -> Association:
        return self.cones.associate(pose)
    def __call__(self, k0: float) -> float:
        return self.evaluate(k0)[0]

    def evaluate(self, k0: float) -> tuple[float, float]:
        """``f(k₀)`` and its standard error (NaN, NaN: no patch)."""
        ks = np.asarray(k0 + STEP * np.arange(-10, 11), dtype=np.float64)

        def associate() -> Association:
            return self._associate(self.poses(k0))

        association = (associate() if self.associations is None else
                       self.associations.get((id(self.source), self.bias, k0), associate))
        return self._fit(association, ks, self.placed.poses_many(ks, self.bias * (1.0 + ks)))

    def _fit(self, association: Association, candidates: F64,
             poses: F64) -> tuple[float, float]:
        """The candidate (parabola-refined) minimising the patches' Cauchy loss, and its
        standard error: the cluster-robust sandwich variance of the M-estimate,
        ``Σ_patches (Σ ψ(r)·∂r/∂θ)² / (Σ ψ'(r)·(∂r/∂θ)²)²``, patches as clusters (their
        echoes share the offset and the visit). ``poses[j]``: the echoes' poses under
        ``candidates[j]``."""
        idx, patch, nx, ny, phi = association
        if self.tilt:  # patches with a residual left beside their offset and orientation
            keep = np.bincount(patch)[patch] >= MIN_TILTED_PATCH_ECHOES
            idx, nx, ny, phi = idx[keep], nx[keep], ny[keep], phi[keep]
            patch = np.unique(patch[keep], return_inverse=True)[1].ravel()
        n = int(patch.max(initial=-1)) + 1
        if n == 0:
            return math.nan, math.nan
        count = np.bincount(patch, minlength=n)
        e = self.echoes
        rows = []
        for j in range(len(candidates)):
            pose = poses[j][idx]
            ox, oy = transform_points(pose, e.sx[idx], e.sy[idx])
            ray = pose[:, 2] + phi
            dx, dy, r = np.cos(ray), np.sin(ray), e.range_m[idx]
            q = nx * ox + ny * oy + r * (nx * dx + ny * dy)
            q = q - (np.bincount(patch, q, n) / count)[patch]
            if self.tilt:  # the patch's orientation: q's trend along it eliminated
                along = ny * (ox + r * dx) - nx * (oy + r * dy)  # the hit, along the patch
                along = along - (np.bincount(patch, along, n) / count)[patch]
                spread = np.bincount(patch, along * along, n)
                trend = np.bincount(patch, along * q, n) / np.maximum(spread, 1e-12)
                q = q - np.where(spread > TILT_MIN_SPREAD_M2, trend, 0.0)[patch] * along
            rows.append(q)
        residuals = np.array(rows)
        mid, step = len(candidates) // 2, float(candidates[1] - candidates[0])
        s = CAUCHY * MAD_SIGMA * float(np.median(np.abs(residuals[mid]))) + 1e-9
        loss = np.log1p((residuals / s) ** 2).sum(axis=1)
        i = int(np.argmin(loss))
        best = float(candidates[i])
        if 0 < i < len(candidates) - 1:
            a, b, c = loss[i - 1], loss[i], loss[i + 1]
            if a - 2 * b + c > 0:
                best = float(candidates[i] + step * 0.5 * (a - c) / (a - 2 * b + c))
        # The residuals are linear over a step: r and ∂r/∂θ at the best from its neighbours.
        j = int(np.clip(round((best - float(candidates[0])) / step), 1, len(candidates) - 2))
        dr = (residuals[j + 1] - residuals[j - 1]) / (2 * step)
        if not np.any(np.abs(dr) > UNMOVED_M):  # no echo moves with the parameter (no
            return math.nan, math.nan  # travel): its minimum would be round-off's choice
        r = residuals[j] + dr * (best - float(candidates[j]))
        psi = 2 * r / (s * s + r * r)
        dpsi = 2 * (s * s - r * r) / (s * s + r * r) ** 2
        info = float((dpsi * dr * dr).sum())
        score = np.bincount(patch, psi * dr, n)
        se = math.sqrt(float((score * score).sum())) / info if info > 0 else math.nan
        return best, se

    def fixed_point(self) -> FixedPoint:
        """The scale: the fixed point of ``f`` (module docstring), its standard error that
        of ``f`` nearest it amplified by ``1 / (1 − c)``."""
        return fixed_points([self])[0]


def fixed_points(estimators: list[SurfaceScale]) -> list[FixedPoint]:
    """:meth:`SurfaceScale.fixed_point` of each, all their evaluations on parallel threads
    (:func:`pipeline.refine.threads.parallel_map`). The line through ``f`` at :data:`K0S` is
    not extrapolated: where an estimator's fixed point lies beyond the window of ``k₀``
    (and it ``recentre``s), the window moves a :data:`K0_STEP` towards it — ``f`` evaluated
    at the new end — and the line is fitted again, until the point lies within (its centre
    at most :data:`K0_MAX_CENTRE` steps from 0, never back)."""
    evaluated: list[dict[int, tuple[float, float]]] = [{} for _ in estimators]  # by k₀ step
    centre = [0] * len(estimators)  # each window's centre, in K0_STEPs
    found = [FixedPoint(math.nan, math.nan, (), math.nan)] * len(estimators)
    todo = list(range(len(estimators)))
    while todo:
        jobs = [(i, centre[i] + j) for i in todo for j in K0_OFFSETS
                if centre[i] + j not in evaluated[i]]
        done = parallel_map(lambda job: estimators[job[0]].evaluate(job[1] * K0_STEP), jobs)
        for (i, step), f in zip(jobs, done, strict=True):
            evaluated[i][step] = f
        moved = []
        for i in todo:
            steps = [centre[i] + j for j in K0_OFFSETS]
            found[i] = _fixed_point(np.array(steps) * K0_STEP, [evaluated[i][j] for j in steps])
            towards = beyond(found[i].value, steps[0] * K0_STEP, steps[-1] * K0_STEP)
            # moved only outwards from 0 (never back), at most K0_MAX_CENTRE steps
            if (estimators[i].recentre and towards != 0 and towards * centre[i] >= 0
                    and abs(centre[i] + towards) <= K0_MAX_CENTRE):
                centre[i] += towards
                moved.append(i)
        todo = moved
    return found


def beyond(value: float, low: float, high: float) -> int:
    """+1 / −1 where ``value`` lies above / below ``[low, high]``, else 0 (NaN: 0)."""
    return 1 if value > high else -1 if value < low else 0


def _row_ids(key: I64) -> I64:
    """Each row's rank among the distinct rows of ``key`` in lexicographic order (what
    ``np.unique(key, axis=0, return_inverse=True)`` numbers them), by one integer per row."""
    if key.shape[0] == 0:
        return np.empty(0, np.int64)
    low = key.min(axis=0)
    span = key.max(axis=0) - low + 1
    if float(np.prod(span.astype(np.float64))) >= 2.0**62:  # too wide for one int64
        return np.unique(key, axis=0, return_inverse=True)[1].ravel()
    flat = np.zeros(key.shape[0], np.int64)
    for j in range(key.shape[1]):
        flat = flat * span[j] + (key[:, j] - low[j])
    return np.unique(flat, return_inverse=True)[1].ravel()


def _fixed_point(x0: F64, evaluated: list[tuple[float, float]]) -> FixedPoint:
    fs = [v[0] for v in evaluated]
    if not all(math.isfinite(v) for v in fs):
        return FixedPoint(math.nan, math.nan, tuple(fs), math.nan)
    c, a = np.polyfit(x0, np.array(fs), 1)
    if c >= 1:
        return FixedPoint(math.nan, float(c), tuple(fs), math.nan)
    value = float(a / (1.0 - c))
    nearest = int(np.argmin(np.abs(x0 - value)))
    return FixedPoint(value, float(c), tuple(fs), evaluated[nearest][1] / (1.0 - c))


@dataclass(frozen=True)
class FixedPoint:
    """The value found (the scale error or the heading bias; NaN: undetermined), the slope
    ``c`` of ``f`` (near 1: the data hardly move the answer), ``f`` at the starting values
    and the value's standard error (statistical only: the estimator's lean is not in it)."""

    value: float
    slope: float
    f: tuple[float, ...]
    standard_error: float
