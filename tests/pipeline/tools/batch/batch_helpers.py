"""Small deterministic CSV logs for the batch tests: a robot driving past two walls."""

from __future__ import annotations

from pathlib import Path

import numpy as np

# Sensor mounts (all at the base origin): beam widths and limits for the CSV logs.
CONFIG_TOML = """\
[grid]
resolution = 0.1

[[sensors.mounts]]
name = "left"
yaw_deg = 90.0
fov_deg = 20.0
min_range = 0.1
max_range = 5.0

[[sensors.mounts]]
name = "right"
yaw_deg = -90.0
fov_deg = 20.0
min_range = 0.1
max_range = 5.0

[[sensors.mounts]]
name = "front"
yaw_deg = 0.0
fov_deg = 20.0
min_range = 0.1
max_range = 5.0
"""

WALL_LEFT_Y = 2.0  # m
WALL_RIGHT_Y = -1.5  # m
FRONT_WALL_X = 12.0  # m


def write_config(path: Path, extra: str = "") -> Path:
    path.write_text(CONFIG_TOML + extra, encoding="utf-8")
    return path


def write_wall_log(path: Path, steps: int = 100, seed: int = 0, speed: float = 0.05) -> Path:
    """A single-layout CSV log: ``steps`` poses 0.1 s apart along +x at y = 0, yaw 0; at
    each the three sonars (left, right, front) read once (3 * steps readings)."""
    rng = np.random.default_rng(seed)
    t = np.arange(steps) * 0.1
    x = np.arange(steps) * speed
    rows = ["t,x,y,yaw,sensor,range"]
    truth = {"left": np.full(steps, WALL_LEFT_Y), "right": np.full(steps, -WALL_RIGHT_Y),
             "front": FRONT_WALL_X - x}
    for i in range(steps):
        for k, name in enumerate(("left", "right", "front")):
            r = truth[name][i] + rng.normal(0.0, 0.01)
            rng_text = "inf" if r > 5.0 else f"{r:.4f}"
            ts = t[i] + 0.001 * k
            rows.append(f"{ts:.3f},{x[i]:.4f},0.0,0.0,{name},{rng_text}")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def write_corrupt_log(path: Path) -> Path:
    """A file that is a CSV log by its header but has a malformed row."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("t,x,y,yaw,sensor,range\n0.0,0.0,0.0,0.0,left,2.0\n0.1,zero,0,0,left,2\n",
                    encoding="utf-8")
    return path
