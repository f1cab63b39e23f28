"""How emulated sonar readings compare with the laser, per building (issue 57's check).

Each reading of the 8 front Pioneer sonars, emulated from a laser log, is compared with
the laser returns inside ±7.5° of its axis (from the sonar's origin) and put in one class,
in this order:

- ``no laser``: no laser return in that cone closer than the sonar's max range;
- ``agrees``: within 10 cm or 10 % of the nearest such return;
- ``no echo``: reads max range although the laser sees an obstacle closer than 4.5 m;
- ``shorter``: shorter than the nearest return (the wide cone answered first);
- ``longer``: the rest (a farther surface or a multipath ghost answered).

A real Pioneer 3-DX with a laser in the same records gave (256 readings, issue 57):
agrees 18 %, no echo 21 %, shorter 20 %, no laser 22 %, longer 19 %.

    python -m benchmarks.sonar_outcomes [--model realistic|ideal|both] [--logs LOG...]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
import numpy.typing as npt

from formats.angles import wrap_angle
from formats.arrays import F64
from formats.laser_log import LaserLog

REPO = Path(__file__).resolve().parent.parent
BUILDINGS = {
    "Intel lab": REPO / "sample_logs/intel-lab/intel-corrected.log.gz",
    "Freiburg 101": REPO / "sample_logs/radish/freiburg-101-corrected.log.gz",
    "Örebro": REPO / "sample_logs/radish/orebro-corrected.log.gz",
    "FHW museum": REPO / "sample_logs/radish/fhw-corrected.log.gz",
    "Belgioioso": REPO / "sample_logs/radish/belgioioso-corrected.log.gz",
}
CLASSES = ("agrees", "no echo", "shorter", "no laser", "longer")
TARGET = {"agrees": 18, "no echo": 21, "shorter": 20, "no laser": 22, "longer": 19}
HALF_CONE = math.radians(7.5)
NEAR_M = 4.5


def outcome_classes(
    log: LaserLog, sonar_x: F64, sonar_y: F64, sonar_yaw: F64, max_range: F64, ranges: F64
) -> npt.NDArray[np.int64]:
    """(S, K) class index into :data:`CLASSES` of each reading ``ranges`` (S, K)."""
    m = log.laser_mount
    valid = log.valid_returns()
    r = np.where(valid, log.ranges, 0.0)
    th = np.where(valid, log.angles, 0.0) + m.yaw
    ex, ey = m.x + r * np.cos(th), m.y + r * np.sin(th)
    dx = ex[:, None, :] - sonar_x[None, :, None]
    dy = ey[:, None, :] - sonar_y[None, :, None]
    bearing = wrap_angle(np.arctan2(dy, dx) - sonar_yaw[None, :, None])
    inside = valid[:, None, :] & (np.abs(bearing) <= HALF_CONE)
    near = np.where(inside, np.hypot(dx, dy), np.inf).min(axis=2)
    tol = np.maximum(0.10, 0.10 * near)
    out = np.full(ranges.shape, CLASSES.index("longer"))
    no_echo = ranges >= max_range[None, :]
    out[(ranges < near - tol) | np.isneginf(ranges)] = CLASSES.index("shorter")
    out[no_echo & (near < NEAR_M)] = CLASSES.index("no echo")
    out[np.abs(ranges - near) <= tol] = CLASSES.index("agrees")
    out[near >= max_range[None, :]] = CLASSES.index("no laser")
    return out


def shares(log_path: Path, model: str, seed: int = 0) -> dict[str, float]:
    """Percent of readings per class for one laser log emulated with ``model``."""
    from pipeline.config import Config
    from pipeline.tools.emulate import emulate, load_laser_log, mounts_from_config, ring_from_mounts
    from pipeline.tools.sonar import SonarPhysics

    log = load_laser_log(log_path)
    ring = ring_from_mounts(mounts_from_config(Config()))
    physics = SonarPhysics() if model == "realistic" else None
    em = emulate(log, ring, physics=physics, seed=seed)
    sub = em.ring
    cls = outcome_classes(log, sub.x, sub.y, sub.yaw, sub.max_range, em.ranges)
    counts = np.bincount(cls.reshape(-1), minlength=len(CLASSES))
    return {c: 100.0 * float(counts[i]) / cls.size for i, c in enumerate(CLASSES)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", choices=("realistic", "ideal", "both"), default="both")
    ap.add_argument("--logs", nargs="*", type=Path, help="laser logs (default: the 5 buildings)")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    logs = {p.name: p for p in a.logs} if a.logs else BUILDINGS
    models = ("ideal", "realistic") if a.model == "both" else (a.model,)
    head = "| building | model | " + " | ".join(CLASSES) + " | s |"
    print(head)
    print("|" + "---|" * (len(CLASSES) + 3))
    print("| real Pioneer (issue 57) | real | "
          + " | ".join(f"{TARGET[c]}" for c in CLASSES) + " | |")
    mean: dict[str, list[float]] = {m: [] for m in models}
    for name, path in logs.items():
        for model in models:
            t0 = time.perf_counter()
            sh = shares(path, model, a.seed)
            dt = time.perf_counter() - t0
            print(f"| {name} | {model} | " + " | ".join(f"{sh[c]:.1f}" for c in CLASSES)
                  + f" | {dt:.1f} |", flush=True)
            mean[model].append(float(np.mean([abs(sh[c] - TARGET[c]) for c in CLASSES
                                              if c != "no laser"])))
    for model in models:
        print(f"{model}: mean |share − target| over agrees/no echo/shorter/longer, per "
              f"building: {', '.join(f'{v:.1f}' for v in mean[model])} points")
    return 0


if __name__ == "__main__":
    sys.exit(main())
