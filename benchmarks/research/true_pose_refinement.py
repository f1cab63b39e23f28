"""What ``--refine-poses`` costs logs whose poses are already right (issue 63: "Correct
poses: refinement costs ≤ 0.01 F1"): every log of ``make compare`` with a ground truth —
the office, corridor and orchard simulations and the five buildings, with the ideal sonar
and with the realistic one — mapped unrefined and refined, both scored against the truth.

Usage::

    python -m benchmarks.research.true_pose_refinement [--compare DIR] [--samples DIR]
        [--only NAME ...] [--work DIR]

``--compare``: ``make compare``'s directory (default ``build/compare``), ``--samples``:
the sample logs (default ``sample_logs``). Prints one row per log: F1 unrefined, refined,
their difference, and what the calibration found (scale estimate ± error, z, scale and
heading bias applied), with the CPU seconds of both runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

WORLDS = ("office", "corridor", "orchard")
BUILDINGS = ("intel", "freiburg-101", "orebro", "fhw", "belgioioso")


def true_pose_logs(compare: Path, samples: Path) -> list[tuple[str, Path, Path, Path]]:
    """(name, log, truth map, truth trajectory) of the 16 logs (8 ideal, 8 realistic)."""
    logs = []
    for w in WORLDS:
        d = samples / w
        logs.append((w, d / f"{w}.mcap", d / f"{w}.truth.yaml", d / f"{w}.truth.csv"))
    for b in BUILDINGS:
        d = samples / "intel-lab" if b == "intel" else compare
        logs.append((b, d / f"{b}.mcap", d / f"{b}.laser.yaml", d / f"{b}.truth.csv"))
    for w in WORLDS:
        s = f"{w}-realistic"
        logs.append((s, compare / f"{s}.mcap", compare / f"{s}.truth.yaml",
                     compare / f"{s}.truth.csv"))
    for b in BUILDINGS:
        s = f"{b}-realistic"
        logs.append((s, compare / f"{s}.mcap", compare / f"{s}.laser.yaml",
                     compare / f"{s}.truth.csv"))
    return logs


def main(argv: list[str] | None = None) -> int:
    from pipeline.config import Config
    from pipeline.run import run
    from pipeline.tools.evaluate import evaluate_run

    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--compare", type=Path, default=Path("build/compare"))
    ap.add_argument("--samples", type=Path, default=Path("sample_logs"))
    ap.add_argument("--only", nargs="+", metavar="NAME")
    ap.add_argument("--work", type=Path)
    ap.add_argument("--refined-only", action="store_true",
                    help="skip the unrefined runs (F1 unrefined printed as NaN)")
    args = ap.parse_args(argv)
    refine = Config(pose_refinement=dataclasses.replace(Config().pose_refinement, enabled=True))
    print("| log | F1 true poses | F1 refined | Δ | scale estimate ± error (z) | applied: "
          "scale, bias °/m | graph | CPU s unrefined / refined |")
    print("|---|---:|---:|---:|---|---|---|---|")
    with tempfile.TemporaryDirectory(prefix="sonarmap-truepose-") as tmp:
        work = args.work or Path(tmp)
        for name, log, truth, traj in true_pose_logs(args.compare, args.samples):
            if args.only and name not in args.only:
                continue
            f1: dict[str, float] = {}
            cpu: dict[str, float] = {}
            pr: dict[str, Any] = {}
            for key, cfg in (("true", Config()), ("refined", refine)):
                if key == "true" and args.refined_only:
                    f1[key], cpu[key] = math.nan, math.nan
                    continue
                out = work / name / key
                c0 = time.process_time()
                result = run(log, out, cfg, force=True)
                cpu[key] = time.process_time() - c0
                pr = result.metrics.pose_refinement or pr
                f1[key] = evaluate_run(out, truth, trajectory=traj, tolerance_m=0.10,
                                       truth_trajectory=traj).f1
            est = (f"{pr.get('scale_estimate', math.nan):+.2%} ± "
                   f"{pr.get('scale_standard_error', math.nan):.2%} "
                   f"({pr.get('scale_z', math.nan):.1f})")
            print(f"| {name} | {f1['true']:.3f} | {f1['refined']:.3f} | "
                  f"{f1['refined'] - f1['true']:+.3f} | {est} | "
                  f"{pr.get('search_scale_error', math.nan):+.2%}, "
                  f"{pr.get('search_heading_bias_deg_per_m', math.nan):+.2f} | "
                  f"{'applied' if pr.get('accepted') else 'no'} | "
                  f"{cpu['true']:.1f} / {cpu['refined']:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
