"""Where a scale-error search lands on TRUE poses (issue 17): scores over the scale error
``k`` (heading bias 0) on the true-pose log of every drifted case, so any peak away from 0
is the score's own bias.

Usage::

    python -m benchmarks.research.scale_bias [--cases NAME ...] [--work DIR]

Scores, each evaluated at ``k`` = −6 … +6 % in 1 % steps on the echoes refinement collects
(``max_echo_range_m``, thinned evenly to 2,500), the peak placed by a parabola through the
best step and its neighbours:

* ``consistency``: the echo-consistency score ``calibration_max_scale`` searches
  (:mod:`pipeline.refine.calibration`) at its cells (0.1 m, σ 0.1 m, free up to 2σ short);
* ``consistency fine``: the same at 0.02 m cells, σ 0.03 m (about the ranges' noise);
* ``held-out likelihood``: the readings' log-likelihood under the standard forward sonar
  model — the cone before the range free, something occupied on the arc at the range:
  ``Σ_cone log(1 − p) + log(1 − Π_arc (1 − p))`` — with the occupancy ``p = (H + a·p₀) /
  (H + F + a)`` (``a = 1``, ``p₀ = 0.3``; ``H``, ``F`` the blurred hit and free counts)
  estimated from the *other* half of the readings (even against odd: cross-fitted, so no
  reading scores against itself), summed over both halves;
* ``range rate``: how range changes compare with the odometry's displacement along the
  surface normal, with the *truth map's* normals (an oracle: :mod:`benchmarks.research.range_rate`),
  the two robust fits that bracket it and the number of echo pairs they had.

The drifted cases' true-pose logs are those of ``compare_methods --drifted`` (the
buildings' are emulated into ``build/compare`` when missing; ``--work`` keeps the drifted
logs that listing also makes).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import numpy as np

from formats.arrays import F64
from pipeline.refine.echoes import Echoes
from pipeline.refine.scores import MAX_ECHOES_CONSISTENCY, Consistency, Placed, thin
from pipeline.se2 import transform_points

SCALES = np.round(np.arange(-0.06, 0.0601, 0.01), 3)


class HeldOutLikelihood(Placed):
    """The cross-fitted forward-model log-likelihood per reading (module docstring)."""

    def __init__(self, t_ns: np.ndarray, x: F64, y: F64, yaw: F64, echoes: Echoes, *,
                 res: float = 0.1, sigma: float = 0.1, prior: float = 1.0, p0: float = 0.3):
        super().__init__(t_ns, x, y, yaw, echoes, MAX_ECHOES_CONSISTENCY)
        keep = thin(len(echoes), MAX_ECHOES_CONSISTENCY)
        bx, by = echoes.arc(1.0)  # the whole beam, as the consistency score
        self.bx, self.by, self.r = bx[keep], by[keep], echoes.range_m[keep]
        self.fold = np.arange(keep.shape[0]) % 2  # even / odd readings
        self.res, self.sigma, self.prior, self.p0 = res, sigma, prior, p0

    def __call__(self, k: float, b: float) -> float:
        from scipy.ndimage import gaussian_filter

        pose = self.poses(k, b)
        wx, wy = self.arcs(pose)
        ox, oy = transform_points(pose, self.sx, self.sy)
        steps = (np.arange(int(self.r.max() / self.res) + 1) + 0.5) * self.res
        free = np.broadcast_to(steps[None, None, :] < (self.r[:, None, None] - self.res),
                               (*wx.shape, steps.size))  # the cone up to a cell short
        ux, uy = (wx - ox[:, None]) / self.r[:, None], (wy - oy[:, None]) / self.r[:, None]
        fx = ox[:, None, None] + ux[..., None] * steps
        fy = oy[:, None, None] + uy[..., None] * steps
        x0, y0 = float(wx.min()) - 1.0, float(wy.min()) - 1.0
        w = int((float(wx.max()) + 1.0 - x0) / self.res) + 1
        h = int((float(wy.max()) + 1.0 - y0) / self.res) + 1

        def cells(px: F64, py: F64) -> np.ndarray:
            return (np.clip(((py - y0) / self.res).astype(np.int64), 0, h - 1) * w
                    + np.clip(((px - x0) / self.res).astype(np.int64), 0, w - 1))

        arc_cell, free_cell = cells(wx, wy), cells(fx, fy)
        blurred = []
        for f in (0, 1):
            m = self.fold == f
            counts = [np.bincount(arc_cell[m].ravel(), minlength=h * w),
                      np.bincount(free_cell[m][free[m]], minlength=h * w)]
            blurred.append([gaussian_filter(c.astype(np.float64).reshape(h, w),
                                            self.sigma / self.res, mode="constant",
                                            truncate=3.0).ravel() for c in counts])
        total = 0.0
        for f in (0, 1):
            m = self.fold == f
            hits, frees = blurred[1 - f]  # the other half's evidence
            log_empty = np.log1p(-(hits + self.prior * self.p0) / (hits + frees + self.prior))
            cone = np.where(free[m], log_empty[free_cell[m]], 0.0).sum(axis=(1, 2))
            arc = np.log(np.maximum(1.0 - np.exp(log_empty[arc_cell[m]].sum(axis=1)), 1e-12))
            total += float((cone + arc).sum())
        return total / max(len(self.fold), 1)


def peak(values: F64) -> float:
    """The scale of the best value, placed by a parabola through it and its neighbours."""
    i = int(np.argmax(values))
    if 0 < i < len(values) - 1:
        a, b, c = values[i - 1], values[i], values[i + 1]
        den = a - 2 * b + c
        if den < 0:
            return float(SCALES[i] + 0.01 * 0.5 * (a - c) / den)
    return float(SCALES[i])


def log_echoes(log: Path, max_range_m: float | None = None
               ) -> tuple[tuple[np.ndarray, F64, F64, F64], Echoes]:
    """The odometry track ``(t_ns, x, y, yaw)`` of ``log`` and the echoes refinement
    collects from it (the default configuration; out to ``max_range_m`` when given, else
    to ``max_echo_range_m``)."""
    from formats import open_log
    from pipeline.config import Config
    from pipeline.refine import collect_echoes
    from pipeline.run import surveyed
    from pipeline.stages.pose_sync import pose_gap_limit_s

    cfg = Config()
    pr = cfg.pose_refinement
    with open_log(log, cfg) as reader:
        sv, sensors = surveyed(reader, cfg)
        gap = round(pose_gap_limit_s(0, sv.track.median_interval_s()) * 1e9)
        echoes = collect_echoes(sv.ordered_ranges(reader), sv.track, sensors,
                                eps_max=cfg.mapper.eps_max,
                                max_echo_range_m=(pr.max_echo_range_m if max_range_m is None
                                                  else max_range_m),
                                time_offset_ns=0, max_gap_ns=gap)
    tr = sv.track
    return (np.asarray(tr.t_ns), np.asarray(tr.x), np.asarray(tr.y), np.asarray(tr.yaw)), echoes


def drifted_cases(doc: str, argv: list[str] | None) -> list[tuple[str, Path, Path, Path, Path]]:
    """The drifted cases ``--cases`` names (default: the synthetic ones), made in ``--work``
    when missing: ``(name, true-pose log, drifted log, truth map, truth trajectory)``."""
    from benchmarks.compare_methods import SYNTHETIC_DRIFT_CASES, _drift_cases

    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=list(SYNTHETIC_DRIFT_CASES), metavar="NAME")
    ap.add_argument("--work", type=Path, default=Path("build/compare/drifted"))
    args = ap.parse_args(argv)
    return _drift_cases(args.work, tuple(args.cases))


def main(argv: list[str] | None = None) -> int:
    from benchmarks.research.range_rate import range_rate_scale
    from pipeline.config import Config

    cases = drifted_cases(__doc__ or "", argv)
    pr = Config().pose_refinement
    print("| true-pose log | echoes | consistency: peak k | consistency fine: peak k "
          "| held-out likelihood: peak k | range rate, truth normals: k fwd / rev (pairs) |")
    print("|---|---:|---:|---:|---:|---|")
    for name, clean, _, truth, _ in cases:
        track, echoes = log_echoes(clean)
        scores: list[Callable[[float, float], float]] = [
            Consistency(*track, echoes, res=2 * pr.field_resolution_m, sigma=pr.field_sigma_m),
            Consistency(*track, echoes, res=0.02, sigma=0.03),
            HeldOutLikelihood(*track, echoes),
        ]
        peaks = [peak(np.array([s(float(k), 0.0) for k in SCALES])) for s in scores]
        rate = range_rate_scale(echoes, truth)
        print(f"| {name} | {len(echoes)} | " + " | ".join(f"{p:+.3f}" for p in peaks)
              + f" | {rate.k_forward:+.3f} / {rate.k_reverse:+.3f} ({rate.pairs}) |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
