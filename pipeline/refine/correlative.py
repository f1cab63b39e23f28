"""Correlative scan-to-submap matching that reports a distribution, not a best cell.

The reference points (earlier submaps placed by the current estimate) become a blurred
evidence field (:meth:`LikelihoodField.of_points`, values in [0, 1)). A candidate pose
``p`` of the query submap gets the log-likelihood

    ℓ(p) = Σ_e log(ε + max_arc f(p ⊕ e)),   ε = OUTLIER

over its echoes ``e`` (an echo lies somewhere on its arc; ``ε`` is the chance that an
echo hits nothing the reference saw). Where the reference's beams never looked (outside
the cones from its sensors to its echoes) ``f`` is the occupancy prior ½ instead: a query
echo there is neither confirmed nor contradicted, which keeps the search from pulling new
wall onto the reference's old wall. Every pose of a grid ``± window`` around the
prediction is evaluated (Olson 2009: exhaustive, so no local minimum), coarse to fine:
first on a field blurred to the coarse step with poses every coarse step, then on finer
levels around its optimum. The match is the posterior
over the fine grid, ``w ∝ exp(ℓ − ℓ_max)``:

* ``pose`` and ``cov``: the weighted mean and covariance of the grid poses (plus each
  step's quantisation ``step²/12``), plus the coarse level's spread over the whole window
  (the fine levels span ± two coarse steps and would cut a flat posterior there): a
  corridor's flat direction gives a wide covariance instead of an arbitrary peak;
* ``score``: the mean field value at the best pose (how much of the query the reference
  explains), ``ambiguity``: the best coarse ℓ farther than two coarse steps from the
  optimum, as a likelihood ratio ``exp(ℓ_other − ℓ_max)`` (near 1: another pose fits as
  well: a repeated structure).

Compiled kernels with numpy references, no randomness: the same input gives the same bits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from formats.angles import wrap_angle
from formats.arrays import F64

F32 = npt.NDArray[np.float32]

OUTLIER = 0.05  # field value an echo gets where the reference saw nothing (a floor)
UNSEEN = 0.5  # field value where the reference's beams never looked (the occupancy prior)


@dataclass(frozen=True)
class LikelihoodField:
    """``values[row, col]`` over cells of ``res`` m; row 0 at ``origin_y`` (min y)."""

    origin_x: float
    origin_y: float
    res: float
    values: F32

    @staticmethod
    def of_points(x: F64, y: F64, *, res: float, sigma: float, margin: float) -> LikelihoodField:
        """The evidence field of arc points ``(x, y)`` over their box grown by ``margin``:
        their density ``ρ`` (splatted bilinearly) blurred by a Gaussian of ``sigma`` m, as
        ``1 − exp(−ρ/ρ_med)`` (``ρ_med`` the median over cells with evidence), so a wall seen
        by few echoes counts nearly as much as one seen by many. Arcs of echoes from different
        viewpoints cross where the obstacle is, so its cells hold the most evidence."""
        from pipeline.refine.kernels import gaussian_blur

        x, y = x.ravel(), y.ravel()
        x0 = math.floor((float(x.min()) - margin) / res) * res
        y0 = math.floor((float(y.min()) - margin) / res) * res
        w = math.ceil((float(x.max()) + margin - x0) / res) + 2
        h = math.ceil((float(y.max()) + margin - y0) / res) + 2
        # Each point is splatted bilinearly over the four cells around it (no res/2 bias).
        fx, fy = (x - x0) / res - 0.5, (y - y0) / res - 0.5
        ix, iy = np.floor(fx).astype(np.int64), np.floor(fy).astype(np.int64)
        ax, ay = fx - ix, fy - iy
        flat = np.zeros(h * w)
        for dx, dy, wt in ((0, 0, (1 - ax) * (1 - ay)), (1, 0, ax * (1 - ay)),
                           (0, 1, (1 - ax) * ay), (1, 1, ax * ay)):
            flat += np.bincount((iy + dy) * w + ix + dx, weights=wt, minlength=h * w)
        counts = flat.reshape(h, w)
        dens = gaussian_blur(counts, sigma / res)
        level = float(np.median(dens[dens > 0.01 * dens.max()])) if dens.max() > 0 else 1.0
        vals = (1.0 - np.exp(-dens / level)).astype(np.float32)
        return LikelihoodField(x0, y0, res, vals)

    def sample(self, x: F64, y: F64) -> F64:
        """Bilinear field values at points (0 outside the field)."""
        x, y = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64))
        h, w = self.values.shape
        fx = (x - self.origin_x) / self.res - 0.5
        fy = (y - self.origin_y) / self.res - 0.5
        x0 = np.floor(fx).astype(np.int64)
        y0 = np.floor(fy).astype(np.int64)
        ax, ay = fx - x0, fy - y0
        out = np.zeros(np.shape(x))
        for dx, dy, wt in ((0, 0, (1 - ax) * (1 - ay)), (1, 0, ax * (1 - ay)),
                           (0, 1, (1 - ax) * ay), (1, 1, ax * ay)):
            cx, cy = x0 + dx, y0 + dy
            ok = (cx >= 0) & (cx < w) & (cy >= 0) & (cy < h)
            out[ok] += wt[ok] * self.values[cy[ok], cx[ok]]
        return out


@dataclass(frozen=True)
class Window:
    """Half-widths of a search (m, rad) and its coarse steps (m, rad)."""

    xy: float
    yaw: float
    step_xy: float
    step_yaw: float


@dataclass(frozen=True)
class Correlation:
    pose: F64  # (3,) weighted mean pose of the query frame in the field's frame
    cov: F64  # (3, 3)
    score: float  # mean field value of the echoes at the best pose
    ambiguity: float  # likelihood ratio of the best distinct pose, in [0, 1]


def _coverage(fld: LikelihoodField, rx: F64, ry: F64, sx: F64, sy: F64, sigma: float
              ) -> np.ndarray:
    """Cells the reference's beams looked at: along each ray from an echo's sensor to each
    of its arc points and ``2σ`` beyond (a wall there would have answered; behind it the
    echo says nothing). Compiled (:func:`pipeline.refine.kernels.beam_coverage`;
    :func:`_coverage_reference` in numpy)."""
    from pipeline.refine.kernels import beam_coverage

    h, w = fld.values.shape
    rx, ry = np.ascontiguousarray(rx, np.float64), np.ascontiguousarray(ry, np.float64)
    sx, sy = np.ascontiguousarray(sx, np.float64), np.ascontiguousarray(sy, np.float64)
    length = np.hypot(rx - sx[:, None], ry - sy[:, None])
    reach = length + 2 * sigma
    n = max(2, math.ceil(float(reach.max()) / (0.5 * fld.res)) + 1)
    return np.asarray(beam_coverage(rx, ry, sx, sy, length, np.linspace(0.0, 1.0, n),
                                    2 * sigma, fld.origin_x, fld.origin_y, fld.res, h, w))


def _coverage_reference(fld: LikelihoodField, rx: F64, ry: F64, sx: F64, sy: F64,
                        sigma: float) -> np.ndarray:
    """:func:`_coverage` in numpy (the kernel's tests compare the two)."""
    h, w = fld.values.shape
    dx, dy = rx - sx[:, None], ry - sy[:, None]
    length = np.hypot(dx, dy)
    reach = length + 2 * sigma
    n = max(2, math.ceil(float(reach.max()) / (0.5 * fld.res)) + 1)
    u = np.linspace(0.0, 1.0, n)
    scale = (reach / np.maximum(length, 1e-9))[..., None] * u
    px = sx[:, None, None] + dx[..., None] * scale
    py = sy[:, None, None] + dy[..., None] * scale
    ix = np.floor((px - fld.origin_x) / fld.res).astype(np.int64).ravel()
    iy = np.floor((py - fld.origin_y) / fld.res).astype(np.int64).ravel()
    ok = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
    cover = np.zeros(h * w, bool)
    cover[iy[ok] * w + ix[ok]] = True
    return cover.reshape(h, w)


def _table(fld: LikelihoodField, cover: np.ndarray, neutral: float) -> F64:
    """Each cell's log value (the field where the beams looked, else ``neutral``), then one
    more for outside the field."""
    table = np.where(cover, np.log(OUTLIER + fld.values.astype(np.float64)), neutral).ravel()
    return np.concatenate([table, [neutral]])


def _loglik(fld: LikelihoodField, cover: np.ndarray, neutral: float, qx: F64, qy: F64,
            centre: F64, dyaw: F64, offsets: F64) -> F64:
    """ℓ over poses ``centre + (offsets[a], offsets[b], dyaw[k])``: (yaw, x, y), compiled
    (:func:`pipeline.refine.kernels.correlation_grid`; :func:`_loglik_reference` in numpy)."""
    from pipeline.refine.kernels import correlation_grid

    h, w = fld.values.shape
    cells = np.round(offsets / fld.res).astype(np.int64)
    return np.asarray(correlation_grid(
        _table(fld, cover, neutral), h, w, np.ascontiguousarray(qx.ravel()),
        np.ascontiguousarray(qy.ravel()), qx.shape[1], np.asarray(centre, np.float64),
        fld.origin_x, fld.origin_y, fld.res, np.asarray(dyaw, np.float64), cells))


def _loglik_reference(fld: LikelihoodField, cover: np.ndarray, neutral: float, qx: F64,
                      qy: F64, centre: F64, dyaw: F64, offsets: F64) -> F64:
    """:func:`_loglik` in numpy (the kernel's tests compare the two)."""
    n_echo, n_arc = qx.shape
    fx, fy = qx.ravel(), qy.ravel()
    h, w = fld.values.shape
    table = _table(fld, cover, neutral)
    cells = np.round(offsets / fld.res).astype(np.int64)
    out = np.empty((dyaw.shape[0], cells.shape[0], cells.shape[0]))
    for k, da in enumerate(dyaw.tolist()):
        th = centre[2] + da
        c, s = math.cos(th), math.sin(th)
        ix = np.floor((centre[0] + c * fx - s * fy - fld.origin_x) / fld.res).astype(np.int64)
        iy = np.floor((centre[1] + s * fx + c * fy - fld.origin_y) / fld.res).astype(np.int64)
        cx = ix[:, None, None] + cells[None, :, None]
        cy = iy[:, None, None] + cells[None, None, :]
        idx = np.where((cx >= 0) & (cx < w) & (cy >= 0) & (cy < h), cy * w + cx, h * w)
        best = table[idx].reshape(n_echo, n_arc, cells.shape[0], cells.shape[0]).max(axis=1)
        out[k] = best.sum(axis=0)
    return out


def _evidence(ref_x: F64, ref_y: F64, ref_sx: F64, ref_sy: F64, res: float, sigma: float,
              ray: float) -> tuple[LikelihoodField, np.ndarray, float]:
    """The reference's field, the cells its beams covered, and the value of a place they
    did not: an unobserved place is occupied with the prior probability ``UNSEEN``. The
    field spans only what its beams covered (``ray``: the longest from a sensor to its
    echo's arc; 2σ beyond the echo; the blur's 3σ reach): elsewhere every pose scores
    ``UNSEEN`` whatever the field would hold."""
    margin = ray + 3 * sigma + 2 * res
    fld = LikelihoodField.of_points(ref_x, ref_y, res=res, sigma=sigma, margin=margin)
    cover = _coverage(fld, ref_x, ref_y, ref_sx, ref_sy, sigma)
    return fld, cover, math.log(OUTLIER + UNSEEN)


def _grid(half: float, step: float) -> F64:
    n = max(1, round(half / step))
    return np.arange(-n, n + 1, dtype=np.float64) * step


def _moments(ll: F64, off: F64, dyaw: F64, cells: bool = True) -> tuple[F64, F64]:
    """Mean and covariance of the posterior ``w ∝ exp(ℓ − ℓ_max)`` over the grid of poses
    ``(dyaw[k], off[a], off[b])``; with ``cells``, plus each step's quantisation
    (``step²/12``) and half a step's uncertainty of where in its cell the optimum lies."""
    wts = np.exp(ll - ll.max())
    wts /= wts.sum()
    d = [np.broadcast_to(off[None, :, None], ll.shape), np.broadcast_to(off[None, None, :],
         ll.shape), np.broadcast_to(dyaw[:, None, None], ll.shape)]
    mean = np.array([float((wts * v).sum()) for v in d])
    cov = np.empty((3, 3))
    for i in range(3):
        for j in range(i, 3):
            cov[i, j] = cov[j, i] = float((wts * (d[i] - mean[i]) * (d[j] - mean[j])).sum())
    if not cells:
        return mean, cov
    step = float(off[1] - off[0]) if off.shape[0] > 1 else 0.0
    step_yaw = float(dyaw[1] - dyaw[0]) if dyaw.shape[0] > 1 else 0.0
    cov += np.diag([step**2 / 12 + (0.5 * step) ** 2, step**2 / 12 + (0.5 * step) ** 2,
                    step_yaw**2 / 12 + (0.5 * step_yaw) ** 2])
    return mean, cov


def correlate(ref_x: F64, ref_y: F64, ref_sx: F64, ref_sy: F64, qx: F64, qy: F64,
              prediction: F64, window: Window, *, res: float, sigma: float
              ) -> Correlation | None:
    """Match the query arcs ``qx, qy`` (echoes × arc samples, in the query frame) against
    the reference arcs ``ref_x, ref_y`` (world, echoes × arc samples) seen from sensors at
    ``ref_sx, ref_sy`` around ``prediction`` (see the module docstring); None when either
    side has fewer than 3 echoes."""
    if ref_x.shape[0] < 3 or qx.shape[0] < 3:
        return None
    ray = float(np.hypot(ref_x - ref_sx[:, None], ref_y - ref_sy[:, None]).max())
    coarse, cover_c, neutral_c = _evidence(ref_x, ref_y, ref_sx, ref_sy, window.step_xy,
                                           max(sigma, window.step_xy), ray)
    dyaw_c, off_c = _grid(window.yaw, window.step_yaw), _grid(window.xy, window.step_xy)
    mid = qx.shape[1] // 2  # a field blurred wider than the arc: its middle point scores it
    cx_, cy_ = ((qx[:, mid:mid + 1], qy[:, mid:mid + 1]) if window.step_xy >= 4 * res
                else (qx, qy))
    ll_c = _loglik(coarse, cover_c, neutral_c, cx_, cy_, prediction, dyaw_c, off_c)
    k, a, b = np.unravel_index(int(np.argmax(ll_c)), ll_c.shape)
    if k in (0, len(dyaw_c) - 1) or a in (0, len(off_c) - 1) or b in (0, len(off_c) - 1):
        return None  # the optimum lies on the window's edge: the true pose may be outside
    centre = prediction + np.array([off_c[a], off_c[b], dyaw_c[k]])
    # ambiguity: the best coarse pose two coarse steps or more away from the optimum
    ga = np.abs(dyaw_c - dyaw_c[k])[:, None, None] > 2 * window.step_yaw
    gxy = np.hypot(off_c[:, None] - off_c[a], off_c[None, :] - off_c[b])[None] > 2 * window.step_xy
    far = np.broadcast_to(ga | gxy, ll_c.shape)
    ambiguity = float(np.exp(ll_c[far].max() - ll_c[k, a, b])) if far.any() else 0.0
    fine, ll, dyaw_f, off_f = coarse, ll_c, dyaw_c, off_c
    step_xy, step_yaw = window.step_xy, window.step_yaw
    if res >= step_xy:  # one level: the coarse grid is the posterior
        centre = prediction
    while res < step_xy:  # the next level: ± two steps of this one, steps a quarter as long
        dyaw_f, off_f = _grid(2 * step_yaw, step_yaw / 4), _grid(2 * step_xy, max(res, step_xy / 4))
        step_xy, step_yaw = max(res, step_xy / 4), step_yaw / 4
        fine, cover, neutral = _evidence(ref_x, ref_y, ref_sx, ref_sy, step_xy,
                                         max(sigma, step_xy), ray)
        ll = _loglik(fine, cover, neutral, qx, qy, centre, dyaw_f, off_f)
        if res < step_xy:
            k, a, b = np.unravel_index(int(np.argmax(ll)), ll.shape)
            centre = centre + np.array([off_f[a], off_f[b], dyaw_f[k]])
    mean, cov = _moments(ll, off_f, dyaw_f)
    if fine is not coarse:  # the fine grid spans ± two coarse steps: a flat posterior is cut
        cov = cov + _moments(ll_c, off_c, dyaw_c, cells=False)[1]  # there; the whole
        # window's spread says how far (a sharp peak's is ~0 on the coarse grid)
    pose = centre + mean
    pose[2] = float(wrap_angle(pose[2]))
    kb = np.unravel_index(int(np.argmax(ll)), ll.shape)
    best = centre + np.array([off_f[kb[1]], off_f[kb[2]], dyaw_f[kb[0]]])
    c, s = math.cos(best[2]), math.sin(best[2])
    vals = fine.sample(best[0] + c * qx - s * qy, best[1] + s * qx + c * qy)
    score = float(vals.reshape(qx.shape).max(axis=1).mean())
    return Correlation(pose, cov, score, ambiguity)
