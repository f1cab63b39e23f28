"""Submap matching: a correlative search of a point set over a likelihood field.

The reference echoes (earlier submaps, placed by the current estimate) are turned into an
**evidence field** (:meth:`LikelihoodField.of_points`: the blurred density of their arc
points). A candidate pose of the query submap scores, per echo, the best field value along
its arc, averaged over the echoes (1: every echo's arc crosses strong evidence). The search (Olson, *Real-time correlative scan
matching*, 2009) evaluates every pose of a grid around the prediction (``± window`` in x,
y and yaw, translations in whole cells so one rotation serves all of them), then refines
the best on 3×3×3 grids of the coarse steps and then their halves, four times, with
bilinear sampling.

What the search reports, so a caller can gate and weight the match:

* ``score`` of the best pose, and ``points`` scored;
* ``ambiguity``: the best score among candidates farther than ``distinct_m`` / ``distinct_deg``
  from the peak, over the peak's score (near 1: another, distinct pose fits as well, as in
  a long corridor or a repeated structure);
* ``cov``: the spread of the candidates around the peak weighted by
  ``exp((score − best)/temperature)``, plus the grid's quantisation and a floor — large
  along a direction the points do not constrain (the axis of a corridor).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from formats.angles import wrap_angle
from formats.arrays import F64

F32 = npt.NDArray[np.float32]


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
class Match:
    """The best pose of the query frame in the field's frame, and how good it is."""

    pose: F64  # (3,)
    cov: F64  # (3, 3), x y yaw
    score: float
    ambiguity: float
    points: int


@dataclass(frozen=True)
class SearchWindow:
    """Half-widths and steps of the grid search (m, rad)."""

    xy: float
    yaw: float
    step_xy: float
    step_yaw: float


def match(
    field: LikelihoodField,
    qx: F64,
    qy: F64,
    prediction: F64,
    window: SearchWindow,
    *,
    temperature: float,
    floor_xy: float,
    floor_yaw: float,
    distinct_m: float,
    distinct_rad: float,
) -> Match:
    """Search the pose of the query arcs around ``prediction``: ``qx, qy`` are (echoes, arc
    samples); an echo scores the best field value along its arc."""
    n_echo, n_arc = qx.shape
    qx, qy = qx.ravel(), qy.ravel()
    cells = max(1, round(window.step_xy / field.res))
    kx = np.arange(-round(window.xy / (cells * field.res)), round(window.xy / (cells * field.res)) + 1)
    offsets = kx * cells  # in cells
    n_yaw = round(window.yaw / window.step_yaw)
    dyaw = np.arange(-n_yaw, n_yaw + 1) * window.step_yaw
    h, w = field.values.shape
    flat = np.concatenate([field.values.ravel(), np.zeros(1, np.float32)])
    outside = h * w
    scores = np.empty((dyaw.shape[0], offsets.shape[0], offsets.shape[0]))
    for a, da in enumerate(dyaw.tolist()):
        th = prediction[2] + da
        c, s = math.cos(th), math.sin(th)
        rx = prediction[0] + c * qx - s * qy
        ry = prediction[1] + s * qx + c * qy
        ix = np.floor((rx - field.origin_x) / field.res).astype(np.int64)
        iy = np.floor((ry - field.origin_y) / field.res).astype(np.int64)
        cx = ix[:, None, None] + offsets[None, :, None]
        cy = iy[:, None, None] + offsets[None, None, :]
        idx = np.where((cx >= 0) & (cx < w) & (cy >= 0) & (cy < h), cy * w + cx, outside)
        scores[a] = flat[idx].reshape(n_echo, n_arc, *idx.shape[1:]).max(axis=1).mean(axis=0)
    best = np.unravel_index(int(np.argmax(scores)), scores.shape)
    best_score = float(scores[best])
    step = cells * field.res
    gx = offsets[None, :, None] * field.res
    gy = offsets[None, None, :] * field.res
    ga = dyaw[:, None, None]
    bx, by, ba = float(gx[0, best[1], 0]), float(gy[0, 0, best[2]]), float(dyaw[best[0]])
    far = (np.hypot(gx - bx, gy - by) > distinct_m) | (np.abs(ga - ba) > distinct_rad)
    far = np.broadcast_to(far, scores.shape)
    ambiguity = float(scores[far].max() / best_score) if far.any() and best_score > 0 else 0.0
    # Spread of the score around the peak.
    wts = np.exp((scores - best_score) / temperature)
    wsum = float(wts.sum())
    d = [np.broadcast_to(gx - bx, scores.shape), np.broadcast_to(gy - by, scores.shape),
         np.broadcast_to(ga - ba, scores.shape)]
    cov = np.empty((3, 3))
    for i in range(3):
        for j in range(i, 3):
            cov[i, j] = cov[j, i] = float((wts * d[i] * d[j]).sum() / wsum)
    cov += np.diag([floor_xy**2 + step**2 / 12, floor_xy**2 + step**2 / 12,
                    floor_yaw**2 + window.step_yaw**2 / 12])
    # Refine: the coarse steps, then halved four times, around the best pose (bilinear).
    pose = np.array([prediction[0] + bx, prediction[1] + by, prediction[2] + ba])
    sxy, syaw = step, window.step_yaw
    grid = np.array([-1.0, 0.0, 1.0])
    for _ in range(5):
        cand_a = pose[2] + grid * syaw
        cand_x = pose[0] + grid * sxy
        cand_y = pose[1] + grid * sxy
        best_val, best_pose = -1.0, pose
        for th in cand_a.tolist():
            c, s = math.cos(th), math.sin(th)
            rx = c * qx - s * qy
            ry = s * qx + c * qy
            px = cand_x[:, None, None] + rx[None, None, :]
            py = cand_y[None, :, None] + ry[None, None, :]
            vals = field.sample(px, py).reshape(3, 3, n_echo, n_arc).max(axis=3).mean(axis=2)
            k = np.unravel_index(int(np.argmax(vals)), vals.shape)
            if vals[k] > best_val + 1e-12:
                best_val = float(vals[k])
                best_pose = np.array([cand_x[k[0]], cand_y[k[1]], th])
        pose = best_pose
        sxy, syaw = sxy / 2, syaw / 2
    pose[2] = float(wrap_angle(pose[2]))
    final = float(field.sample(
        pose[0] + math.cos(pose[2]) * qx - math.sin(pose[2]) * qy,
        pose[1] + math.sin(pose[2]) * qx + math.cos(pose[2]) * qy,
    ).reshape(n_echo, n_arc).max(axis=1).mean())
    return Match(pose, cov, final, ambiguity, n_echo)
