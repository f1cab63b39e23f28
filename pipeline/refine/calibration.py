"""Odometry calibration from map sharpness: the scale error and heading bias that make the
echoes agree best.

Wheel odometry errs mostly systematically — a wheel radius off by a few percent, a
wheelbase or gyro bias that turns the heading by a fraction of a degree per metre (the
:mod:`pipeline.drift` model). Two numbers shared by the whole run are far better
determined by all the echoes at once than by any local match. For a candidate scale error
``k`` and heading bias ``b``, the odometry is re-integrated with the inverse model
(:func:`pipeline.drift.apply_drift`), every echo's arc points are placed in the world, and
the **sharpness** of their density is measured: ``Σ ρ² / (Σ ρ)²`` of the Gaussian-blurred
histogram (Rényi's quadratic entropy, up to a sign and a log; Sheehan et al. used it to
calibrate lidars). Walls seen from places far apart along the path coincide only under the
right calibration, so sharpness peaks there. The search evaluates a grid over
``±max_scale`` × ``±max_bias`` (bias steps that turn the heading by at most 4° over the
whole path) and refines around the best twice (steps divided by 4).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from formats.arrays import F64, I64
from pipeline.drift import DriftModel, apply_drift
from pipeline.refine.echoes import Echoes
from pipeline.refine.se2 import transform_points

MAX_ECHOES = 8_000  # echoes used for the sharpness (evenly thinned beyond)


@dataclass(frozen=True)
class Calibration:
    """The odometry's estimated scale error (fraction) and heading bias (rad per metre)."""

    scale_error: float
    heading_bias: float
    sharpness: float
    sharpness_uncalibrated: float

    def correct(self, x: F64, y: F64, yaw: F64) -> tuple[F64, F64, F64]:
        """Odometry poses with this calibration's error removed."""
        inverse = DriftModel(
            scale_error=1.0 / (1.0 + self.scale_error) - 1.0,
            heading_bias_deg_per_m=-math.degrees(self.heading_bias) / (1.0 + self.scale_error),
        )
        return apply_drift(x, y, yaw, inverse)


class _Sharpness:
    """Sharpness of the echoes' density under a candidate calibration."""

    def __init__(self, t_ns: I64, x: F64, y: F64, yaw: F64, echoes: Echoes, *,
                 res: float, sigma: float):
        keep = np.arange(len(echoes))
        if keep.shape[0] > MAX_ECHOES:
            keep = np.linspace(0, len(echoes) - 1, MAX_ECHOES).round().astype(np.int64)
        # The echoes' odometry poses are spliced into the pose sequence (by stamp), so one
        # re-integration gives the calibrated pose of every echo too.
        t_all = np.concatenate([t_ns, echoes.t_ns[keep]])
        order = np.argsort(t_all, kind="stable")
        odo = echoes.odo[keep]
        self.x = np.concatenate([x, odo[:, 0]])[order]
        self.y = np.concatenate([y, odo[:, 1]])[order]
        self.yaw = np.concatenate([yaw, odo[:, 2]])[order]
        where = np.empty(order.shape[0], np.int64)
        where[order] = np.arange(order.shape[0])
        self.echo_at = where[t_ns.shape[0]:]
        self.bx, self.by = echoes.bx[keep], echoes.by[keep]
        self.res, self.sigma = res, sigma

    def __call__(self, k: float, b: float) -> float:
        cal = Calibration(k, b, 0.0, 0.0)
        x, y, yaw = cal.correct(self.x, self.y, self.yaw)
        i = self.echo_at
        pose = np.column_stack([x[i], y[i], yaw[i]])[:, None, :]
        wx, wy = transform_points(pose, self.bx, self.by)
        return density_sharpness(wx.ravel(), wy.ravel(), self.res, self.sigma)


def density_sharpness(x: F64, y: F64, res: float, sigma: float) -> float:
    """``Σ ρ² / (Σ ρ)²`` of the points' histogram blurred by a Gaussian of ``sigma`` m."""
    from scipy.ndimage import gaussian_filter

    x0, y0 = float(x.min()) - 4 * sigma, float(y.min()) - 4 * sigma
    w = int((float(x.max()) + 4 * sigma - x0) / res) + 1
    h = int((float(y.max()) + 4 * sigma - y0) / res) + 1
    cell = ((y - y0) / res).astype(np.int64) * w + ((x - x0) / res).astype(np.int64)
    hist = np.bincount(cell, minlength=h * w).reshape(h, w).astype(np.float64)
    dens = gaussian_filter(hist, sigma / res, mode="constant", truncate=3.0)
    total = float(dens.sum())
    return float((dens * dens).sum() / (total * total)) if total > 0 else 0.0


def calibrate(
    t_ns: I64, x: F64, y: F64, yaw: F64, echoes: Echoes, *, max_scale: float,
    max_bias: float, res: float, sigma: float,
) -> Calibration:
    """The sharpest calibration on the grid (see the module docstring); ``max_scale = 0``
    searches the heading bias alone."""
    f = _Sharpness(t_ns, x, y, yaw, echoes, res=res, sigma=sigma)
    base = f(0.0, 0.0)
    ks = np.linspace(-max_scale, max_scale, 11 if max_scale > 0 else 1)
    # The heading error a bias step makes grows with the path: steps of at most 4° over
    # the whole run (13 to 401 values), so a long run's sharp optimum is not stepped over.
    path = float(np.hypot(np.diff(x), np.diff(y)).sum())
    n_bias = int(np.clip(math.ceil(2 * math.degrees(max_bias) * path / 4.0) + 1, 13, 401))
    bs = np.linspace(-max_bias, max_bias, n_bias | 1)
    best = (base, 0.0, 0.0)
    for k in ks.tolist():
        for b in bs.tolist():
            v = f(k, b)
            if v > best[0] + 1e-15:
                best = (v, k, b)
    dk = float(ks[1] - ks[0]) if ks.shape[0] > 1 else 0.0
    db = float(bs[1] - bs[0])
    for _ in range(2):
        dk, db = dk / 4, db / 4
        _, k0, b0 = best
        for k in sorted(set((k0 + dk * np.arange(-4, 5)).tolist())):
            for b in (b0 + db * np.arange(-4, 5)).tolist():
                v = f(k, b)
                if v > best[0] + 1e-15:
                    best = (v, k, b)
    return Calibration(best[1], best[2], best[0], base)
