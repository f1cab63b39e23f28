"""Pose refinement on drifted logs other than ``make compare``'s (3 %, 0.8°/m): the other
sign of either error, smaller and larger ones, and noise per step, on the office
simulation and the Intel lab emulation; then the same kinds of drift on the buildings,
the corridor and the orchard, and the buildings' sonars emulated as the Udacity 8-sonar
ring — logs the refinement was not developed on — two worlds of repeating structure
(a warehouse's shelving, a hall of pillars) and two floors (a loop corridor, rooms off a
corridor), all four in ``sample_logs/worlds``, and the floors seen by the Pioneer's 8
front sonars and by one servo-swept sonar (presets ``pioneer-p3dx-front``,
``hc-sr04-sweep3``), an L-shaped office (turned 25°), and the four buildings at −4 %.
What refinement finds and what it gives.

    python -m benchmarks.drift_variety [--work DIR] [--cases office intel-lab ...]
        [--presets none hc-sr04-sweep3 ...] [--config TOML]

Each row: the drift model, F1 of the default method on true poses / the drifted odometry /
refined, refined/true, the same after the refined trajectory's SE(2) alignment to the
true one (what is left when the map's frame, not its shape, is wrong), F1 of the true
poses refined (its cost), ATE drifted → refined (evo's SE(2)-aligned RMSE) and the
calibration found (``metrics.json`` → ``pose_refinement``: the scale applied or, in
brackets, the estimate gated out; its z); a last line counts the rows that reach 0.9×
(``Tally``). ``--config`` sets the refined runs' ``[pose_refinement]``. A run's outputs are kept under
``--work`` (default ``build/drift_variety``); the drifted logs are made there when missing.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
TARGET = 0.9  # the issue's: refined F1 at least 0.9× the F1 of true poses

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
# (case, sonar preset or None, model, drift seed): every model on the office and the Intel
# (seeded by the model's row), then the others.
ROWS: tuple[tuple[str, str | None, tuple[str, float, float, float, float], int], ...] = (
    *((case, None, model, i) for case in ("office", "intel-lab") for i, model in enumerate(MODELS)),
    ("fhw", None, MODELS[0], 3),
    ("freiburg-101", None, MODELS[0], 3),
    ("orebro", None, ("+2 %, -1.0°/m", 0.02, -1.0, 0.0, 0.0), 3),
    ("freiburg-101", None, ("+3 %, +0.8°/m, noise 0.01 m/√m", 0.03, 0.8, 0.01, 0.0), 5),
    ("fhw", None, MODELS[5], 5),
    ("intel-lab", "udacity-8sonar", ("+3 %, +0.8°/m", 0.03, 0.8, 0.0, 0.0), 1),
    ("fhw", "udacity-8sonar", ("+3 %, +0.8°/m", 0.03, 0.8, 0.0, 0.0), 1),
    ("corridor", None, MODELS[0], 0),
    ("orchard", None, MODELS[0], 0),
    ("corridor", None, MODELS[4], 0),
    ("orchard", None, MODELS[4], 0),
    ("fhw", None, MODELS[4], 7),
    ("freiburg-101", None,
     ("-3 %, +0.5°/m, noise 0.02 m/√m, 0.002 rad/√rad", -0.03, 0.5, 0.02, 0.002), 8),
    # repeating structure, where sharpness is fooled (calibration.py _consistent_bias)
    ("warehouse", None, ("+3 %, +0.8°/m", 0.03, 0.8, 0.0, 0.0), 0),
    ("pillars", None, ("+3 %, +0.8°/m", 0.03, 0.8, 0.0, 0.0), 0),
    ("warehouse", None, ("-2.5 %, -1.0°/m, noise 0.01 m/√m", -0.025, -1.0, 0.01, 0.0), 0),
    ("pillars", None, ("-2.5 %, -1.0°/m, noise 0.01 m/√m", -0.025, -1.0, 0.01, 0.0), 0),
    # two more floors made after the refinement was (a loop corridor, rooms off a corridor)
    ("loop", None, ("+3 %, +0.8°/m", 0.03, 0.8, 0.0, 0.0), 0),
    ("rooms", None, ("+3 %, +0.8°/m", 0.03, 0.8, 0.0, 0.0), 0),
    ("loop", None, ("-2.5 %, -1.0°/m, noise 0.01 m/√m", -0.025, -1.0, 0.01, 0.0), 0),
    ("rooms", None, ("-2.5 %, -1.0°/m, noise 0.01 m/√m", -0.025, -1.0, 0.01, 0.0), 0),
    # the floors seen by the Udacity 8-sonar ring
    ("rooms", "udacity-8sonar", ("+3 %, +0.8°/m", 0.03, 0.8, 0.0, 0.0), 0),
    ("loop", "udacity-8sonar", ("+3 %, +0.8°/m", 0.03, 0.8, 0.0, 0.0), 0),
    ("warehouse", "udacity-8sonar", ("+3 %, +0.8°/m", 0.03, 0.8, 0.0, 0.0), 0),
    ("pillars", "udacity-8sonar", ("+3 %, +0.8°/m", 0.03, 0.8, 0.0, 0.0), 0),
    # ... and by the Pioneer's 8 front sonars
    *((world, "pioneer-p3dx-front", ("+3 %, +0.8°/m", 0.03, 0.8, 0.0, 0.0), 0)
      for world in ("office", "corridor", "rooms", "loop", "warehouse", "pillars")),
    # ... and by one sonar on a servo, sweeping three bearings
    *((world, "hc-sr04-sweep3", ("+3 %, +0.8°/m", 0.03, 0.8, 0.0, 0.0), 0)
      for world in ("office", "corridor", "rooms", "loop", "warehouse", "pillars")),
    # an L-shaped office (turned 25°), made after the rows above
    *(("skew", preset, model, 0) for preset in (None, "pioneer-p3dx-front")
      for model in (("+3 %, +0.8°/m", 0.03, 0.8, 0.0, 0.0),
                    ("+4 %, +1.2°/m, noise 0.002 rad/√rad", 0.04, 1.2, 0.0, 0.002))),
    # the buildings at −4 %, beyond the window the scale's line was first fitted over
    # (surfaces.fixed_points), made after the rows above
    *((case, None, ("-4 %, -0.5°/m", -0.04, -0.5, 0.0, 0.0), 0)
      for case in ("intel-lab", "fhw", "freiburg-101", "orebro")),
)
CASES = tuple(dict.fromkeys(row[0] for row in ROWS))


def found(pr: dict[str, Any]) -> str:
    """The calibration a refined run found: the scale applied, or [its estimate] gated out."""
    scale = pr.get("search_scale_error", math.nan)
    text = (f"{scale:+.3f}" if scale or "scale_estimate" not in pr
            else f"[{pr['scale_estimate']:+.3f}]")
    return (f"{text}, {pr.get('search_heading_bias_deg_per_m', math.nan):+.2f}°/m "
            f"({pr.get('scale_z', math.nan):.1f})")


@dataclass(frozen=True)
class Scored:
    """One run scored against the truth: F1 in the truth's frame and after the rigid motion
    that lays its trajectory onto the true one (``pipeline.tools.evaluate``'s ``aligned``: a
    heading error in the first metres turns the whole map without changing its shape), the
    ATE of its trajectory (evo's SE(2)-aligned RMSE) and its refinement's metrics."""

    f1: float
    f1_aligned: float
    ate: float
    refinement: dict[str, Any]


def scored_run(log: Path, out: Path, cfg: Any, truth: Path, traj: Path) -> Scored:
    """``log`` run with ``cfg`` into ``out``, scored against the map ``truth`` and the
    trajectory ``traj``."""
    from pipeline.run import run
    from pipeline.tools.evaluate import evaluate_run

    result = run(log, out, cfg, force=True)
    ev = evaluate_run(out, truth, trajectory=traj, truth_trajectory=traj)
    ate = ev.trajectory_error["ate_rmse_m"] if ev.trajectory_error else math.nan
    aligned = float(ev.aligned["f1"]) if ev.aligned else math.nan
    return Scored(ev.f1, aligned, float(ate), result.metrics.pose_refinement or {})


@dataclass
class Tally:
    """The rows' summary line: how many refined maps reach ``TARGET`` × the F1 of true
    poses, in the truth's frame and aligned, their means, and the true poses' worst cost."""

    refined: list[float] = field(default_factory=list)  # refined / true, per row
    aligned: list[float] = field(default_factory=list)  # aligned refined / true
    cost: list[float] = field(default_factory=list)  # F1 true − F1 true refined

    def add(self, f1_true: float, refined: Scored, f1_true_refined: float) -> None:
        self.refined.append(refined.f1 / f1_true)
        self.aligned.append(refined.f1_aligned / f1_true)
        self.cost.append(f1_true - f1_true_refined)

    def summary(self) -> str:
        n = len(self.refined)
        if n == 0:
            return "no rows"

        def reach(ratios: list[float]) -> str:
            return (f"{sum(r >= TARGET for r in ratios)} / {n} ≥ {TARGET:g}× "
                    f"(mean {sum(ratios) / n:.4f})")

        return (f"refined/true: {reach(self.refined)}; aligned: {reach(self.aligned)}; "
                f"true poses refined cost at most {max(self.cost):.3f} F1")


def refined_config(path: Path | None) -> Any:
    """The default config with refinement on, its ``[pose_refinement]`` from the TOML at
    ``path`` when given (``--config``)."""
    from pipeline.config import Config, load_config

    chosen = load_config(path).pose_refinement if path else Config().pose_refinement
    return Config(pose_refinement=dataclasses.replace(chosen, enabled=True))


def main(argv: list[str] | None = None) -> None:
    from benchmarks.compare_methods import drifted_case
    from pipeline.config import Config
    from pipeline.drift import DriftModel

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", type=Path, default=REPO / "build" / "drift_variety")
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    ap.add_argument("--presets", nargs="+", metavar="PRESET",
                    help="only the rows of these sonar presets ('none': the log's own sonars)")
    ap.add_argument("--config", type=Path, help="TOML whose [pose_refinement] the refined runs use")
    args = ap.parse_args(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    plain = Config()
    refine = refined_config(args.config)
    print("| log | drift (scale, heading bias, noise) | F1 true | F1 drifted | F1 refined "
          "| refined/true | aligned refined/true | F1 true poses refined (cost) "
          "| ATE drifted → refined (m) | scale [gated], bias found (z) |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---|---|")
    truths: dict[str, tuple[float, float]] = {}  # per log: F1 of true poses, refined
    tally = Tally()
    for i, (case, preset, model, seed) in enumerate(ROWS):
        if case not in args.cases or (args.presets and (preset or "none") not in args.presets):
            continue
        log = case if preset is None else f"{case} ({preset})"
        tag = case if preset is None else f"{case}-{preset}"
        # the office's and the Intel's drifted logs keep their names of before (<case>_<model>)
        stem = f"{case}_{seed}" if i < 2 * len(MODELS) else f"{tag}_row{i}"
        drifted = args.work / f"{stem}.mcap"
        clean, truth, traj = drifted_case(case, drifted, DriftModel(*model[1:]),
                                          drift_seed=seed, preset=preset)
        if tag not in truths:
            truths[tag] = (scored_run(clean, args.work / tag / "true", plain, truth, traj).f1,
                           scored_run(clean, args.work / tag / "true_refined", refine, truth,
                                      traj).f1)
        f1_true, f1_true_refined = truths[tag]
        d, r = (scored_run(drifted, args.work / tag / f"{stem}_{key}", cfg, truth, traj)
                for key, cfg in (("drifted", plain), ("refined", refine)))
        tally.add(f1_true, r, f1_true_refined)
        print(f"| {log} | {model[0]} | {f1_true:.3f} | {d.f1:.3f} | {r.f1:.3f} | "
              f"{r.f1 / f1_true:.2f} | {r.f1_aligned / f1_true:.2f} | "
              f"{f1_true_refined:.3f} ({f1_true - f1_true_refined:.3f}) | "
              f"{d.ate:.3f} → {r.ate:.3f} ({d.ate / r.ate:.1f}×) | "
              f"{found(r.refinement)} |", flush=True)
    print(f"\n{tally.summary()}", flush=True)
    print("drift_variety: done", file=sys.stderr, flush=True)


if __name__ == "__main__":
    main()
