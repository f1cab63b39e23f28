"""How well the echoes of a whole run agree when the odometry is re-integrated under a
candidate calibration (scale error ``k``, heading bias ``b``): the scores
:mod:`pipeline.refine.calibration` searches.

For a candidate the odometry is re-integrated with the inverse drift model
(:class:`Placed`: the echoes' own poses spliced into the track, so one re-integration
places them too; compiled, :func:`pipeline.refine.kernels.poses_at`) and every echo's arc
points are placed in the world. Two measures of agreement, for two jobs:

1. **Sharpness** of the arc points' density, ``Σ ρ² / (Σ ρ)²`` of their Gaussian-blurred
   histogram (Rényi's quadratic entropy up to a sign and a log; Sheehan et al. calibrated
   lidars with it): a heading error rotates whole stretches of the run against each other
   and blurs every wall (:class:`Sharpness`; :class:`BinnedSharpness`, its coarse stand-in
   for the scan over the whole bias range: counts in ``2σ`` bins, no blur).
   Sharpness is *biased in scale*: a robot driving along a wall leaves echo points spaced
   by its travel, so a too-short scale packs the same wall into fewer cells and the
   density grows as ``1/(1 + k)`` with no wall moving into place (measured: every log's
   sharpness peaks at the largest scale searched, true poses included). The same happens
   to any score that rewards overlap, including a submap matcher's correlation.
2. **Echo consistency** (:class:`Consistency`) asks instead, at each echo, what the *whole
   log's* evidence says about the cells on its arc: ``H`` = the blurred density of echo arc
   points, ``F`` = the blurred density of points on the echoes' free cones (from the sonar
   to ``2σ`` short of the arc, sampled every cell, as the attribution method counts free
   space, ALGORITHM.md §9); an arc point's consistency is ``H / (H + F)`` — the share of the
   observations of that place that were echoes — and an echo scores the best of its arc
   points that enough evidence covers (the echo came from somewhere on its arc). The score
   is the mean over echoes; both densities are deposited cloud-in-cell and read at each arc
   point's own position, so it moves continuously with the calibration (nearest-cell
   counts made it a step function whose peak moved by ±0.005°/m with the grid's
   orientation). Packing a wall tighter scales ``H`` and ``F`` alike and leaves the ratio
   unchanged; an echo placed where other readings saw free space scores low.

Each score remembers the calibrations it was asked (a score is a pure function of one);
the compiled ones (:class:`CompiledScore`) keep their numpy reference
(``reference=True``) for the tests. Echoes beyond a score's budget are thinned evenly
(:func:`thin`): deterministic, no random draws.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt

from formats.arrays import F64, I64
from pipeline.drift import DriftModel, Steps, systematic_factors
from pipeline.refine.echoes import Echoes
from pipeline.refine.memo import Memo
from pipeline.refine.threads import parallel_map
from pipeline.se2 import transform_points

MAX_ECHOES_SHARPNESS = 8_000  # echoes used for the sharpness (evenly thinned beyond)
MAX_ECHOES_SCAN = 2_000  # ... in the first, binned scan over the whole bias range
MAX_ECHOES_CONSISTENCY = 2_500  # echoes used for the consistency score
MAX_ECHOES_CONSISTENCY_SCAN = 800  # ... in its scan over the whole bias range
MIN_EVIDENCE = 2.0  # an arc point scores where its H + F reaches this (blurred counts)
_A = npt.NDArray[Any]
Segments = tuple[_A, _A, _A, _A, _A, _A, _A, _A, _A]  # kernels.step_segments' arrays


def thin(n: int, at_most: int) -> I64:
    """The indices of at most ``at_most`` of ``n`` items, evenly spread (all when fewer)."""
    if n <= at_most:
        return np.arange(n)
    return np.linspace(0, n - 1, at_most).round().astype(np.int64)


class Placed:
    """A subset of the echoes with the odometry spliced in, placed under a calibration."""

    def __init__(self, t_ns: I64, x: F64, y: F64, yaw: F64, echoes: Echoes, at_most: int):
        self.keep = keep = thin(len(echoes), at_most)  # the echoes kept, by index
        # The echoes' odometry poses are spliced into the pose sequence (by stamp), so one
        # re-integration gives the calibrated pose of every echo too.
        t_all = np.concatenate([t_ns, echoes.t_ns[keep]])
        order = np.argsort(t_all, kind="stable")
        odo = echoes.odo[keep]
        self.x = np.concatenate([x, odo[:, 0]])[order]
        self.y = np.concatenate([y, odo[:, 1]])[order]
        self.yaw = np.concatenate([yaw, odo[:, 2]])[order]
        self.motion = Steps.of(self.x, self.y, self.yaw)  # re-integrated under each calibration
        where = np.empty(order.shape[0], np.int64)
        where[order] = np.arange(order.shape[0])
        self.echo_at = where[t_ns.shape[0]:]
        self.bx, self.by = echoes.bx[keep], echoes.by[keep]
        self.sx, self.sy = echoes.sx[keep], echoes.sy[keep]
        self._known: Memo[tuple[float, float], float] = Memo()  # scores, by (k, b)
        self._segments: Segments | None = None  # poses_many's steps, once

    def poses_many(self, ks: F64, bs: F64) -> F64:
        """(len(ks), echoes, 3): the echoes' poses under each calibration ``(ks[j], bs[j])``
        (compiled: ``self.motion.drifted_many`` at the echoes to ~1e-11 m, the steps
        summed per segment once per distinct bias, :func:`pipeline.refine.kernels.poses_at`)."""
        from pipeline.refine.kernels import poses_at, step_segments

        models = [DriftModel.removing(float(k), float(b)) for k, b in zip(ks, bs, strict=True)]
        m, i = self.motion, self.echo_at
        scale, bias, same = systematic_factors(models)
        given = np.stack([m.x[i], m.y[i], m.yaw[i]], axis=-1)  # the odometry's own poses
        if m.x.shape[0] < 2 or same.all():  # no step, or no calibration: the poses as given
            return np.broadcast_to(given, (len(models), i.shape[0], 3)).copy()
        if self._segments is None:  # the steps' segments: the same for every calibration
            self._segments = step_segments(float(m.yaw[0]), m.lx, m.ly, m.dyaw, m.ds, i)
        out = poses_at(float(m.x[0]), float(m.y[0]), *self._segments, scale, bias)
        out[same] = given  # as drifted_many
        return np.asarray(out)

    def poses(self, k: float, b: float) -> F64:
        """(echoes, 3): the echoes' poses under the calibration ``(k, b)``."""
        return np.asarray(self.poses_many(np.array([k]), np.array([b]))[0])

    def remembered(self, k: float, b: float, score: Callable[[F64], float]) -> float:
        """``score`` of the echoes' poses under ``(k, b)``, computed once per calibration:
        a score is a pure function of it, and the searches ask for the same ones again."""
        return self._known.get((float(k), float(b)), lambda: score(self.poses(k, b)))

    def arcs(self, pose: F64) -> tuple[F64, F64]:
        return transform_points(pose[:, None, :], self.bx, self.by)


class CompiledScore(Placed):
    """A score with a compiled kernel (``_compiled``, of the echoes' poses) and its numpy
    reference (``reference=True``, which the kernel's tests compare it with)."""

    reference: bool = False

    def __call__(self, k: float, b: float) -> float:
        raise NotImplementedError

    def _compiled(self, pose: F64) -> float:
        raise NotImplementedError

    def scan(self, k: float, bs: F64, chunk: int = 64) -> list[float]:
        """The score at ``k`` and each bias of ``bs``, as calls would give (the poses
        integrated ``chunk`` biases at a time, the chunks on parallel threads)."""
        if self.reference:
            return [self(k, float(b)) for b in bs]

        def score(lo: int) -> list[float]:
            part = bs[lo:lo + chunk]
            return [self._compiled(pose) for pose in self.poses_many(np.full(part.shape, k), part)]

        return [v for part in parallel_map(score, range(0, len(bs), chunk)) for v in part]


class Sharpness(Placed):
    """Sharpness of the echoes' density under a candidate calibration."""

    def __init__(self, t_ns: I64, x: F64, y: F64, yaw: F64, echoes: Echoes, *,
                 res: float, sigma: float):
        super().__init__(t_ns, x, y, yaw, echoes, MAX_ECHOES_SHARPNESS)
        self.res, self.sigma = res, sigma

    def __call__(self, k: float, b: float) -> float:
        return self.remembered(k, b, self._score)

    def _score(self, pose: F64) -> float:
        wx, wy = self.arcs(pose)
        return density_sharpness(wx.ravel(), wy.ravel(), self.res, self.sigma)


class BinnedSharpness(CompiledScore):
    """The sharpness's coarse stand-in for the wide scan: ``Σ n² / (Σ n)²`` of the points'
    counts ``n`` in square bins of ``2σ``, averaged over two grids offset by half a bin
    (no blur, and no grid over a box a wrong bias can spread the points across). Compiled
    (:func:`pipeline.refine.kernels.binned_sharpness_placed`, bit for bit the numpy version
    below, ``reference=True``)."""

    def __init__(self, t_ns: I64, x: F64, y: F64, yaw: F64, echoes: Echoes, *, sigma: float,
                 reference: bool = False):
        super().__init__(t_ns, x, y, yaw, echoes, MAX_ECHOES_SCAN)
        self.bin = 2 * sigma
        self.reference = reference

    def _compiled(self, pose: F64) -> float:
        from pipeline.refine.kernels import binned_sharpness_placed

        return float(binned_sharpness_placed(
            np.ascontiguousarray(pose[:, 0]), np.ascontiguousarray(pose[:, 1]),
            np.cos(pose[:, 2]), np.sin(pose[:, 2]), self.bx, self.by, self.bin))

    def __call__(self, k: float, b: float) -> float:
        pose = self.poses(k, b)
        if not self.reference:
            return self._compiled(pose)
        wx, wy = self.arcs(pose)
        total = 0.0
        for shift in (0.0, 0.5):
            ix = np.floor(wx.ravel() / self.bin + shift).astype(np.int64)
            iy = np.floor(wy.ravel() / self.bin + shift).astype(np.int64)
            _, n = np.unique(ix * (1 << 32) + iy, return_counts=True)
            total += float((n.astype(np.float64) ** 2).sum()) / float(n.sum()) ** 2
        return total / 2


class Consistency(CompiledScore):
    """Echo consistency ``H / (H + F)`` under a candidate calibration (module docstring),
    compiled (:mod:`pipeline.refine.kernels`); ``reference=True``: the numpy
    version below, which the kernel's tests compare it with."""

    def __init__(self, t_ns: I64, x: F64, y: F64, yaw: F64, echoes: Echoes, *,
                 res: float, sigma: float, reference: bool = False,
                 at_most: int = MAX_ECHOES_CONSISTENCY):
        super().__init__(t_ns, x, y, yaw, echoes, at_most)
        self.reference = reference
        # The whole cone: an oblique surface's nearest point, which made the echo, lies at
        # the cone's edge (the sharpness's narrower arc would put it in front of the wall).
        self.bx, self.by = echoes.take(self.keep).arc(1.0)
        self.res, self.sigma, self.band = res, sigma, 2 * sigma
        reach = float(np.hypot(self.bx - self.sx[:, None], self.by - self.sy[:, None]).max(
            initial=0.0))
        self.steps = np.arange(1, int(reach / res) + 1) * res  # along each ray, m

    def _compiled(self, pose: F64) -> float:
        from pipeline.refine.kernels import consistency_placed

        return float(consistency_placed(
            np.ascontiguousarray(pose[:, 0]), np.ascontiguousarray(pose[:, 1]),
            np.cos(pose[:, 2]), np.sin(pose[:, 2]), self.bx, self.by, self.sx, self.sy,
            self.steps, self.band, self.res, 4 * self.sigma, self.sigma / self.res,
            self._radius(), MIN_EVIDENCE))

    def _radius(self) -> int:
        """The blur read over ± this many cells (4σ)."""
        return math.ceil(4 * self.sigma / self.res)

    def __call__(self, k: float, b: float) -> float:
        return self.remembered(k, b, self._score)

    def _score(self, pose: F64) -> float:
        if not self.reference:
            return self._compiled(pose)
        best = self.per_echo(pose)
        scored = best >= 0
        return float(best[scored].mean()) if scored.any() else 0.0

    def more_consistent_z(self, a: tuple[float, float], b: tuple[float, float],
                          cluster_m: float) -> float:
        """How many standard errors the echoes are more consistent under the calibration
        ``a`` than under ``b`` (each ``(k, b)``): per echo scored under both, the difference
        of its consistency (:meth:`per_echo`); their mean over its standard error, the
        echoes within each ``cluster_m`` of travel one cluster (neighbours read the same
        cells, so they are not independent observations). NaN: no echo scored under both
        or a single cluster; ±inf where the differences do not vary."""
        from pipeline.refine.submaps import path_length

        ca, cb = self.per_echo(self.poses(*a)), self.per_echo(self.poses(*b))
        both = (ca >= 0) & (cb >= 0)
        travel = path_length(self.x, self.y)[self.echo_at]  # the odometry's, m
        cluster = np.unique(np.floor(travel[both] / cluster_m), return_inverse=True)[1].ravel()
        if cluster.size == 0 or cluster.max() == 0:
            return math.nan
        d = (ca - cb)[both]
        mean = float(d.mean())
        residual = np.bincount(cluster, d - mean)  # each cluster's sum about the mean
        se = math.sqrt(float((residual * residual).sum())) / d.size
        return mean / se if se > 0 else math.copysign(math.inf, mean) if mean else math.nan

    def per_echo(self, pose: F64) -> F64:
        """Each echo's consistency at the poses ``pose`` (the best ratio ``H / (H + F)``
        over its arc; −1 where its arc saw too little evidence): the score is their mean
        (numpy, the kernel's reference)."""
        wx, wy = self.arcs(pose)
        ox, oy = transform_points(pose, self.sx, self.sy)  # each sonar's position
        dx, dy = wx - ox[:, None], wy - oy[:, None]
        r = np.hypot(dx, dy)
        along = self.steps[None, None, :]
        free = along < (r[..., None] - self.band)
        frac = along / np.maximum(r[..., None], 1e-9)
        fx = (ox[:, None, None] + dx[..., None] * frac)[free]
        fy = (oy[:, None, None] + dy[..., None] * frac)[free]
        res, rad, sd = self.res, self._radius(), self.sigma / self.res
        margin = 4 * self.sigma + (rad + 2) * res
        x0 = min(float(wx.min()), float(ox.min())) - margin
        y0 = min(float(wy.min()), float(oy.min())) - margin
        w = int((max(float(wx.max()), float(ox.max())) + margin - x0) / res) + 2
        h = int((max(float(wy.max()), float(oy.max())) + margin - y0) / res) + 2

        def shared(px: F64, py: F64) -> F64:  # cloud in cell: each point over four cells
            u, v = (px.ravel() - x0) / res - 0.5, (py.ravel() - y0) / res - 0.5
            c0, r0 = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
            fc, fr = u - c0, v - r0
            grid = np.zeros((h, w))
            for dr, dc, part in ((0, 0, (1 - fr) * (1 - fc)), (0, 1, (1 - fr) * fc),
                                 (1, 0, fr * (1 - fc)), (1, 1, fr * fc)):
                np.add.at(grid, (r0 + dr, c0 + dc), part)
            return grid

        def weights(at: F64) -> tuple[I64, F64]:  # each point's window and Gaussian weights
            c0 = np.floor(at).astype(np.int64) - rad
            cells = c0[..., None] + np.arange(2 * rad + 2)
            g = np.exp(-0.5 * ((at[..., None] - cells) / sd) ** 2)
            return cells, g / g.sum(axis=-1, keepdims=True)

        cols, wu = weights((wx - x0) / res - 0.5)
        rows, wv = weights((wy - y0) / res - 0.5)

        def read(grid: F64) -> F64:  # the blurred density at each arc point
            window = grid[rows[..., :, None], cols[..., None, :]]
            return np.asarray(np.einsum("nam,naq,namq->na", wv, wu, window))

        hh, ff = read(shared(wx, wy)), read(shared(fx, fy))
        seen = hh + ff
        ratio = np.where(seen >= MIN_EVIDENCE, hh / np.maximum(seen, 1e-12), -1.0)
        return np.asarray(ratio.max(axis=1))


def density_sharpness(x: F64, y: F64, res: float, sigma: float) -> float:
    """``Σ ρ² / (Σ ρ)²`` of the points' histogram blurred by a Gaussian of ``sigma`` m."""
    from pipeline.refine.kernels import gaussian_blur

    x0, y0 = float(x.min()) - 4 * sigma, float(y.min()) - 4 * sigma
    w = int((float(x.max()) + 4 * sigma - x0) / res) + 1
    h = int((float(y.max()) + 4 * sigma - y0) / res) + 1
    cell = ((y - y0) / res).astype(np.int64) * w + ((x - x0) / res).astype(np.int64)
    hist = np.bincount(cell, minlength=h * w).reshape(h, w).astype(np.float64)
    dens = gaussian_blur(hist, sigma / res)
    total = float(dens.sum())
    return float((dens * dens).sum() / (total * total)) if total > 0 else 0.0


def track_consistency(t_ns: I64, x: F64, y: F64, yaw: F64, echoes: Echoes, res: float,
                      sigma: float) -> float:
    """The consistency of ``echoes`` (:class:`Consistency`) placed on the track
    ``(x, y, yaw)`` (stamps ``t_ns``)."""
    return Consistency(t_ns, x, y, yaw, echoes.on_track(t_ns, x, y, yaw), res=2 * res,
                       sigma=sigma)(0.0, 0.0)
