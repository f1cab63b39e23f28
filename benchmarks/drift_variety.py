"""Pose refinement on drift models other than ``make compare``'s (3 %, 0.8°/m): the other
sign of either error, smaller and larger ones, and noise per step, on the office
simulation and the Intel lab emulation. What refinement finds and what it gives.

    python -m benchmarks.drift_variety [--work DIR] [--cases office intel-lab] [--config TOML]

Each row: the drift model, F1 of the default method on true poses / the drifted odometry /
refined, refined/true, ATE drifted → refined (evo's SE(2)-aligned RMSE) and the
calibration found (``metrics.json`` → ``pose_refinement``); ``--config`` sets the refined
runs' ``[pose_refinement]``. A run's outputs are kept under
``--work`` (default ``build/drift_variety``); the drifted logs are made there when missing.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# (label, scale error, heading bias deg/m, noise m/√m, noise rad/√rad)
MODELS = (
    ("-3 %, -0.8°/m", -0.03, -0.8, 0.0, 0.0),
    ("+1.5 %, +0.4°/m", 0.015, 0.4, 0.0, 0.0),
    ("+5 %, -1.5°/m", 0.05, -1.5, 0.0, 0.0),
    ("0, +0.8°/m", 0.0, 0.8, 0.0, 0.0),
    ("+3 %, +0.8°/m, noise 0.02 m/√m", 0.03, 0.8, 0.02, 0.0),
    ("+3 %, +0.8°/m, noise 0.003 rad/√rad", 0.03, 0.8, 0.0, 0.003),
    ("+3 %, +0.8°/m, noise 0.01 m/√m, 0.01 rad/√rad", 0.03, 0.8, 0.01, 0.01),
)


def main(argv: list[str] | None = None) -> None:
    from benchmarks.compare_methods import drifted_case
    from pipeline.config import Config, load_config
    from pipeline.drift import DriftModel
    from pipeline.evaluate import evaluate_run
    from pipeline.run import run

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", type=Path, default=REPO / "build" / "drift_variety")
    ap.add_argument("--cases", nargs="+", default=["office", "intel-lab"],
                    choices=["office", "intel-lab"])
    ap.add_argument("--config", type=Path, help="TOML whose [pose_refinement] the refined runs use")
    args = ap.parse_args(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    plain = Config()
    chosen = load_config(args.config).pose_refinement if args.config else plain.pose_refinement
    refine = Config(pose_refinement=dataclasses.replace(chosen, enabled=True))
    print("| log | drift (scale, heading bias, noise) | F1 true | F1 drifted | F1 refined "
          "| refined/true | ATE drifted → refined (m) | scale, bias found (z) |")
    print("|---|---|---:|---:|---:|---:|---|---|")
    for case in args.cases:
        f1_true = math.nan
        for i, model in enumerate(MODELS):
            drifted = args.work / f"{case}_{i}.mcap"
            clean, truth, traj = drifted_case(case, drifted, DriftModel(*model[1:]),
                                              drift_seed=i)
            if i == 0:
                out = args.work / case / "true"
                run(clean, out, plain, force=True)
                f1_true = evaluate_run(out, truth, trajectory=traj, truth_trajectory=traj).f1
            scores = {}
            for key, cfg in (("drifted", plain), ("refined", refine)):
                out = args.work / case / f"{i}_{key}"
                result = run(drifted, out, cfg, force=True)
                ev = evaluate_run(out, truth, trajectory=traj, truth_trajectory=traj)
                ate = ev.trajectory_error["ate_rmse_m"] if ev.trajectory_error else math.nan
                scores[key] = (ev.f1, float(ate), result.metrics.pose_refinement or {})
            pr = scores["refined"][2]
            print(f"| {case} | {model[0]} | {f1_true:.3f} | {scores['drifted'][0]:.3f} | "
                  f"{scores['refined'][0]:.3f} | {scores['refined'][0] / f1_true:.2f} | "
                  f"{scores['drifted'][1]:.3f} → {scores['refined'][1]:.3f} "
                  f"({scores['drifted'][1] / scores['refined'][1]:.1f}×) | "
                  f"{pr.get('search_scale_error', math.nan):+.3f}, "
                  f"{pr.get('search_heading_bias_deg_per_m', math.nan):+.2f}°/m "
                  f"({pr.get('scale_z', math.nan):.1f}) |", flush=True)
        print(f"{case}: done", file=sys.stderr, flush=True)


if __name__ == "__main__":
    main()
