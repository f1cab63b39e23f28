"""The scale error the surface-patch estimator (:mod:`pipeline.refine.surfaces`) finds on
the true-pose and the drifted log of every drifted case, with the slope of its fixed-point
line, ``f(k₀)`` itself, the estimate's standard error and ``z`` (the estimate over its
error with the systematic part in quadrature: applied at ``calibration_scale_min_z``, 3).

Usage::

    python -m benchmarks.research.scale_surfaces [--cases NAME ...] [--work DIR]

The heading bias is the one refinement's default calibration finds (by sharpness, at
``k = 0``), held per reported metre. The patches are the offset-only ones (the model asked
first), or with ``calibration_scale_tilt = "always"`` those with their orientation fitted.
"""

from __future__ import annotations

import dataclasses
import math

from pipeline.refine.calibration import Lean, scale_z
from pipeline.refine.surfaces import K0S, SurfaceScale


def main(argv: list[str] | None = None) -> int:
    from benchmarks.research.scale_bias import drifted_cases, log_echoes
    from pipeline.config import Config
    from pipeline.refine.refine import configured_calibration

    cases = drifted_cases(__doc__ or "", argv)
    pr = Config().pose_refinement
    print("| log | poses | echoes | heading bias found (°/m) | f(k₀) at k₀ = "
          + ", ".join(f"{k:+.0%}" for k in K0S) + " | slope c | fixed point k | error | z |")
    print("|---|---|---:|---:|---|---:|---:|---:|---:|")
    for name, clean, drifted, _, _ in cases:
        for which, log in (("true", clean), ("drifted", drifted)):
            track, echoes = log_echoes(log)
            bias = configured_calibration(  # the heading bias as refinement finds it
                *track, echoes, dataclasses.replace(pr, calibration_max_scale=0.0)).heading_bias
            fp = SurfaceScale(*track, echoes, bias, pr.calibration_scale_window_m,
                              pr.calibration_scale_tilt == "always").fixed_point()
            z = scale_z(fp, Lean(pr.calibration_scale_systematic,
                                 pr.calibration_scale_systematic_negative))
            print(f"| {name} | {which} | {len(echoes)} | {math.degrees(bias):.2f} | "
                  + " ".join(f"{v:+.4f}" for v in fp.f)
                  + f" | {fp.slope:.2f} | {fp.value:+.4f} | {fp.standard_error:.4f} "
                  f"| {z:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
