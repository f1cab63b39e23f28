"""The robot's true motion: drive straight between waypoints, turn in place at each one.

Motion is a list of knots (time s, x m, y m, unwrapped yaw rad) with constant velocity
between knots, so the pose at any time is an exact linear interpolation of the knots.
Yaw is the heading of the current leg (REP 103: counter-clockwise from +x).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from formats.angles import wrap_angle
from formats.arrays import F64
from formats.errors import ConfigError
from formats.text_file import read_text
from formats.writers.trajectory_tum import Trajectory  # the one stamped-pose type
from pipeline.tools.simulate.world import WORLD_M


@dataclass(frozen=True)
class MotionPlan:
    """Knots of piecewise-constant-velocity motion; ``t_s`` seconds from the start."""

    t_s: F64
    x: F64
    y: F64
    yaw: F64  # unwrapped

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1])

    def pose_at(self, t_s: npt.ArrayLike) -> tuple[F64, F64, F64]:
        """(x, y, unwrapped yaw) at times ``t_s`` (s from the start; clamped to the plan)."""
        t = np.asarray(t_s, dtype=np.float64)
        return (
            np.interp(t, self.t_s, self.x),
            np.interp(t, self.t_s, self.y),
            np.interp(t, self.t_s, self.yaw),
        )


def plan_motion(waypoints: npt.ArrayLike, speed: float, turn_rate: float) -> MotionPlan:
    """Knots for driving through ``waypoints`` (N×2, m) at ``speed`` m/s, turning in place
    at ``turn_rate`` rad/s (shortest way) at each waypoint. The robot starts facing the
    first leg. Repeated waypoints are skipped."""
    wp = np.asarray(waypoints, dtype=np.float64).reshape(-1, 2)
    if not (speed > 0 and turn_rate > 0):
        raise ConfigError(f"speed and turn_rate must be > 0, got {(speed, turn_rate)!r}")
    if wp.shape[0] < 2:
        raise ConfigError(f"need at least 2 waypoints, got {wp.shape[0]}")
    step = np.hypot(*np.diff(wp, axis=0).T)
    keep = np.concatenate([[True], step > 1e-9])
    wp = wp[keep]
    if wp.shape[0] < 2:
        raise ConfigError("all waypoints are the same point")
    d = np.diff(wp, axis=0)
    heading = np.arctan2(d[:, 1], d[:, 0])
    # Shortest rotation between consecutive legs, accumulated into an unwrapped yaw.
    turn = wrap_angle(np.diff(heading))
    yaw_leg = heading[0] + np.concatenate([[0.0], np.cumsum(turn)])
    legs = wp.shape[0] - 1
    # Knots: start, then per leg an arrival, and between legs the end of a turn.
    n = 2 * legs
    t = np.zeros(n)
    x = np.zeros(n)
    y = np.zeros(n)
    yaw = np.zeros(n)
    drive = np.hypot(d[:, 0], d[:, 1]) / speed
    spin = np.abs(turn) / turn_rate
    # Knot 2k = start of leg k (after turning), knot 2k+1 = end of leg k.
    dur = np.empty(n - 1)
    dur[0::2] = drive
    dur[1::2] = spin
    t[1:] = np.cumsum(dur)
    x[0::2], y[0::2] = wp[:-1, 0], wp[:-1, 1]
    x[1::2], y[1::2] = wp[1:, 0], wp[1:, 1]
    yaw[0::2] = yaw_leg
    yaw[1::2] = yaw_leg
    # Zero-duration turns (straight continuations) give duplicate knot times; np.interp
    # handles them, since both knots hold the same pose.
    return MotionPlan(t, x, y, yaw)


def sample_trajectory(plan: MotionPlan, rate_hz: float, start_ns: int) -> Trajectory:
    """True poses at ``rate_hz`` from ``start_ns`` to the end of the plan (ends included)."""
    if not rate_hz > 0:
        raise ConfigError(f"pose_rate_hz must be > 0, got {rate_hz!r}")
    period_ns = 1e9 / rate_hz
    end_ns = round(plan.duration_s * 1e9)
    k = np.arange(int(end_ns // period_ns) + 1, dtype=np.int64)
    rel = np.round(k * period_ns).astype(np.int64)
    if rel[-1] < end_ns:
        rel = np.append(rel, np.int64(end_ns))
    x, y, yaw = plan.pose_at(rel / 1e9)
    return Trajectory(rel + np.int64(start_ns), x, y, wrap_angle(yaw))


def load_waypoints(path: str | Path) -> F64:
    """Waypoints (N×2, m) from a CSV file ``x,y``; header, '#' lines and blanks allowed."""
    p = Path(path)
    text = read_text(p, "waypoint file", errors=(ConfigError, ConfigError))
    rows: list[tuple[float, float]] = []
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    for i, row in enumerate(csv.reader(lines)):
        if i == 0 and [c.strip().lower() for c in row] == ["x", "y"]:
            continue
        try:
            if len(row) != 2:
                raise ValueError(f"expected 2 columns x,y, got {len(row)}")
            xv, yv = float(row[0]), float(row[1])
            if not (WORLD_M.holds(xv) and WORLD_M.holds(yv)):
                raise ValueError(f"a coordinate {WORLD_M.rule()}")
        except ValueError as err:
            raise ConfigError(f"bad waypoint row {i + 1} {row!r}: {err}", p) from err
        rows.append((xv, yv))
    if len(rows) < 2:
        raise ConfigError(f"need at least 2 waypoints, got {len(rows)}", p)
    return np.array(rows, dtype=np.float64)
