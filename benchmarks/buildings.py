"""Pose refinement on real buildings it was not tuned on.

    python -m benchmarks.buildings LOG.log.gz [LOG.log.gz ...] [--work DIR] [--no-odometry]
        [--config TOML]

Each LOG is a CARMEN log with corrected poses (FLASER) and wheel odometry (ODOM), such as
the Radish buildings of ``acschaefer/ple`` (``data/carmen/``: ACES, CSAIL, Freiburg 079,
Seattle, ...; the repository does not carry them: keep it small). Each is emulated as
``make compare`` emulates its four buildings (:func:`benchmarks.compare_methods.drifted_case`'s
sonar ring, the laser map as truth): with its corrected poses, with the issue's drift applied
to them (3 % scale, 0.8°/m, seed 0) and, unless ``--no-odometry``, with its own wheel
odometry; then scored as ``compare_methods --drifted`` scores (true / drifted / refined /
true poses refined: F1, aligned F1, ATE); ``--config`` sets the refined runs'
``[pose_refinement]``. The emulated logs are made under ``--work`` (default
``build/buildings``) when missing.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from benchmarks.compare_methods import (
    DRIFT_BIAS_DEG_PER_M,
    DRIFT_SCALE,
    REPO,
    drift_markdown,
    score_drift_cases,
)
from pipeline.drift import DriftModel


def building_name(log: Path) -> str:
    """``aces-corrected.log.gz`` → ``aces``."""
    name = log.name
    for suffix in (".gz", ".log"):
        name = name.removesuffix(suffix)
    return name.removesuffix("-corrected")


def building_cases(log: Path, work: Path, odometry: bool = True
                   ) -> list[tuple[str, Path, Path, Path, Path]]:
    """The cases of one CARMEN log: drifted by the issue's model and, with ``odometry``,
    its own wheel odometry; both beside the true-pose emulation under ``work``."""
    from formats.errors import InputError
    from pipeline.tools.emulate import EmulateOptions, run_emulation

    name = building_name(log)
    clean = work / name / f"{name}.mcap"
    if not clean.exists():
        clean.parent.mkdir(parents=True, exist_ok=True)
        run_emulation(log, clean, "mcap", options=EmulateOptions(sonar_model="ideal"))
    truth, traj = clean.with_name(f"{name}.laser.yaml"), clean.with_name(f"{name}.truth.csv")
    variants = [("drifted", EmulateOptions(drift=DriftModel(DRIFT_SCALE, DRIFT_BIAS_DEG_PER_M),
                                           drift_seed=0, sonar_model="ideal"))]
    if odometry:
        variants.append(("odometry", EmulateOptions(raw_odometry=True, sonar_model="ideal")))
    cases = []
    for kind, options in variants:
        log_out = clean.with_name(f"{name}-{kind}.mcap")
        if not log_out.exists():
            try:
                run_emulation(log, log_out, "mcap", options=options)
            except InputError as err:  # a log without wheel odometry: its drifted row only
                print(f"{log}: no {kind} row: {err}", file=sys.stderr, flush=True)
                continue
        label = name if kind == "drifted" else f"{name}, real odometry"
        cases.append((label, clean, log_out, truth, traj))
    return cases


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("logs", nargs="+", type=Path, help="CARMEN logs (.log / .log.gz)")
    ap.add_argument("--work", type=Path, default=REPO / "build" / "buildings")
    ap.add_argument("--no-odometry", action="store_true", help="only the drifted rows")
    ap.add_argument("--tolerance", type=float, default=0.10, help="match distance, m")
    ap.add_argument("--config", type=Path, help="TOML whose [pose_refinement] the refined runs use")
    args = ap.parse_args(argv)
    from formats.errors import SonarmapError

    rows = []
    for log in args.logs:
        try:
            cases = building_cases(log, args.work, odometry=not args.no_odometry)
        except SonarmapError as err:
            print(f"{log}: skipped: {err}", file=sys.stderr, flush=True)
            continue
        for case in cases:
            try:  # a case run refuses (a drifted extent beyond grid.max_cells) is reported
                row = score_drift_cases([case], args.work, args.tolerance, args.config)
            except SonarmapError as err:
                print(f"{case[0]}: skipped: {err}", file=sys.stderr, flush=True)
                continue
            rows += row
            print(drift_markdown(row).splitlines()[-1], flush=True)
    print("\n" + drift_markdown(rows))
    drifted = [r for r in rows if not r.name.endswith("real odometry")]
    passed = sum(r.f1_refined >= 0.9 * r.f1_true for r in drifted)
    print(f"\ndrifted: {passed} / {len(drifted)} ≥ 0.9× true; true poses refined cost at most "
          f"{max((r.f1_true - r.f1_true_refined for r in rows), default=0.0):.3f} F1",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
