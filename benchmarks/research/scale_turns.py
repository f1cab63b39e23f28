"""The odometry calibration refinement finds on a log turned as a whole: its odometry and
its echoes' poses rotated about the origin by each angle, so nothing about the log changes
but how the estimators' grids (the surfaces' 10 cm densities and 0.3 m patches, the echo
consistency's cells) fall on it. The spread over the turns is the estimate's quantisation
noise, which its standard error does not hold (benchmarks/RESULTS.md, seventeenth session).

Usage::

    python -m benchmarks.research.scale_turns LOG [LOG ...] [--angles DEG ...] [--truth-scale K]
        [--inject K ...]

Each row: the angle, the scale applied (0 where gated), the surfaces' estimate ± its
standard error, its z and fixed-point slope, whether from the far echoes, and the heading
bias (per metre); a last line per log: the estimates' mean and range, and with
``--truth-scale`` (the drift the log was made with, a fraction) the mean's error.
``--inject``: the odometry first drifted by these further scale errors (one table each,
``pipeline.drift``; the echoes' poses read again from it): an unbiased estimator's answer
moves by what was injected, ``(1 + k)(1 + injected) − 1``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np

from formats.angles import wrap_angle
from formats.arrays import F64
from pipeline.refine.echoes import Echoes

DEFAULT_ANGLES = (0.0, 11.25, 22.5, 33.75, 45.0, 56.25, 67.5, 78.75)


def turned(x: F64, y: F64, yaw: F64, angle: float) -> tuple[F64, F64, F64]:
    """Poses ``(x, y, yaw)`` rotated by ``angle`` (rad) about the origin."""
    c, s = math.cos(angle), math.sin(angle)
    return c * x - s * y, s * x + c * y, wrap_angle(yaw + angle)


def turned_echoes(echoes: Echoes, angle: float) -> Echoes:
    """``echoes`` with their odometry poses rotated as :func:`turned` (their arcs, in the
    base frame, do not move)."""
    x, y, yaw = turned(echoes.odo[:, 0], echoes.odo[:, 1], echoes.odo[:, 2], angle)
    return dataclasses.replace(echoes, odo=np.column_stack([x, y, yaw]))


def main(argv: list[str] | None = None) -> int:
    from benchmarks.research.scale_bias import log_echoes
    from pipeline.config import Config
    from pipeline.drift import DriftModel, apply_drift
    from pipeline.refine.refine import configured_calibration

    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("logs", nargs="+", type=Path)
    ap.add_argument("--angles", nargs="+", type=float, default=list(DEFAULT_ANGLES))
    ap.add_argument("--truth-scale", type=float, help="the scale error the logs were drifted by")
    ap.add_argument("--inject", nargs="+", type=float, default=[0.0],
                    help="further scale errors applied to the odometry first")
    args = ap.parse_args(argv)
    cfg = Config().pose_refinement
    print("| log | injected | turn (°) | scale applied | estimate ± error | z | slope "
          "| far echoes | heading bias (°/m) |")
    print("|---|---:|---:|---:|---|---:|---:|---|---:|")
    for log in args.logs:
        (t, x0, y0, yaw0), logged = log_echoes(log, cfg.echo_reach_m)
        for extra in args.inject:
            x, y, yaw = apply_drift(x0, y0, yaw0, DriftModel(scale_error=extra))
            echoes = logged.on_track(t, x, y, yaw) if extra else logged
            estimates = []
            for deg in args.angles:
                a = math.radians(deg)
                cal = configured_calibration(t, *turned(x, y, yaw, a), turned_echoes(echoes, a),
                                             cfg)
                estimates.append(cal.scale_estimate)
                print(f"| {log.name} | {extra:+.1%} | {deg:g} | {cal.scale_error:+.2%} | "
                      f"{cal.scale_estimate:+.2%} ± {cal.scale_standard_error:.2%} | "
                      f"{cal.scale_z:.2f} | {cal.scale_slope:.2f} | {cal.scale_far_echoes} | "
                      f"{math.degrees(cal.heading_bias):+.4f} |", flush=True)
            mean = float(np.mean(estimates))
            expected = (None if args.truth_scale is None
                        else (1 + args.truth_scale) * (1 + extra) - 1)
            error = "" if expected is None else f", error {mean - expected:+.2%}"
            print(f"\n{log.name}, {extra:+.1%} injected: mean {mean:+.2%} over "
                  f"{len(estimates)} turns, {min(estimates):+.2%} … {max(estimates):+.2%}"
                  f"{error}\n", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
