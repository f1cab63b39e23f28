"""Write the slow-odometry sample log (deterministic): ``python sample_logs/slow-odometry/generate.py``.

A small robot with odometry at about 1 Hz (poses 0.9 s apart, common on small robots)
and one ultrasonic sensor on a servo sweeping three bearings (−40°, 0°, +40°; one reading
every 0.1 s), driving through the lower-left room of the office world. The servo's three
stops are logged as three frames (``sweep_l40``, ``sweep_0``, ``sweep_r40``) with their
mounts in ``sensors.csv``, as a tf tree would give them. Before the pose gap default
adapted to the log's pose rate, every reading of this log fell in a "pose gap" and the
map was empty (issue 12, item 5); the golden keeps that path covered.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.tools.simulate.sonar import cast_rays  # noqa: E402
from pipeline.tools.simulate.world import load_world  # noqa: E402

T0 = 1_700_000_000.0
POSE_DT = 0.9  # s
READING_DT = 0.1  # s
DURATION = 60.0  # s
SPEED = 0.12  # m/s
BEARINGS = {"sweep_l40": 40.0, "sweep_0": 0.0, "sweep_r40": -40.0}  # degrees
FOV = math.radians(25.0)
MIN_RANGE, MAX_RANGE = 0.05, 4.0
WAYPOINTS = np.array([[1.0, 1.0], [4.8, 1.0], [4.8, 3.6], [1.0, 3.6], [1.0, 1.0]])


def pose_at(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position along the waypoint loop at constant speed, heading along the leg."""
    legs = np.diff(WAYPOINTS, axis=0)
    lengths = np.hypot(legs[:, 0], legs[:, 1])
    s = (SPEED * t) % lengths.sum()
    ends = np.cumsum(lengths)
    k = np.searchsorted(ends, s, side="right").clip(0, len(legs) - 1)
    into = s - (ends[k] - lengths[k])
    u = legs[k] / lengths[k, None]
    xy = WAYPOINTS[k] + u * into[:, None]
    return xy[:, 0], xy[:, 1], np.arctan2(u[:, 1], u[:, 0])


def main() -> None:
    rng = np.random.default_rng(12)
    world = load_world(ROOT / "sample_logs" / "worlds" / "office.toml")
    tp = np.arange(0.0, DURATION + 1e-9, POSE_DT)
    px, py, pyaw = pose_at(tp)
    tr = np.arange(0.05, DURATION - 0.1, READING_DT)
    names = list(BEARINGS)
    order = [0, 1, 2, 1]  # the servo sweeps l40 → 0 → r40 → 0 → l40 ...
    sensor = np.array([order[i % len(order)] for i in range(len(tr))])
    rx, ry, ryaw = pose_at(tr)
    theta = ryaw + np.radians([BEARINGS[names[i]] for i in sensor])
    d, _ = cast_rays(world, rx, ry, theta)
    d = d + rng.normal(0.0, 0.01, d.shape)
    d = np.where(d >= MAX_RANGE, np.inf, d)
    poses = ["t,x,y,yaw"] + [
        f"{T0 + t:.3f},{x:.4f},{y:.4f},{a:.5f}" for t, x, y, a in zip(tp, px, py, pyaw, strict=True)
    ]
    ranges = ["t,sensor,range"] + [
        f"{T0 + t:.3f},{names[i]},{'inf' if math.isinf(r) else f'{r:.4f}'}"
        for t, i, r in zip(tr, sensor, d, strict=True)
    ]
    sensors = ["sensor,x,y,yaw,fov,min_range,max_range"] + [
        f"{n},0.1,0.0,{math.radians(b):.6f},{FOV:.6f},{MIN_RANGE},{MAX_RANGE}"
        for n, b in BEARINGS.items()
    ]
    for name, lines in (("poses.csv", poses), ("ranges.csv", ranges), ("sensors.csv", sensors)):
        (HERE / name).write_text("\n".join(lines) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
