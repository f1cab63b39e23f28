"""Emulation: each virtual sonar reads, per laser scan, the shortest laser return inside
its cone (see the package docstring)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from formats.angles import wrap_angle
from formats.arrays import F64, I64
from formats.contract import PoseBatch, SensorMount, make_range_batch
from formats.errors import InputError
from formats.laser_log import LaserLog
from formats.log_writers import LogContent
from pipeline.drift import DriftModel, apply_drift
from pipeline.se2 import compose, inverse
from pipeline.tools.emulate.ring import cone_coverage, laser_view
from pipeline.tools.sonar.model import SonarPhysics
from pipeline.tools.sonar.scan_scene import scan_readings
from pipeline.tools.sonar_ring import SonarRing

CHUNK_CELLS = 2_000_000  # bound on (scan × beam × sonar) and ray samples held at once


def emulate_ranges(log: LaserLog, ring: SonarRing) -> F64:
    """(S, K) sonar readings (m): per scan and sonar, the shortest laser return inside the
    cone; max range when none is closer; −inf when closer than the min range."""
    s_n, b_n = log.ranges.shape
    k_n = len(ring)
    m = log.laser_mount
    valid = log.valid_returns()
    r = np.where(valid, log.ranges, 0.0)
    th = np.where(valid, log.angles, 0.0) + m.yaw
    ex = m.x + r * np.cos(th)  # endpoints in the base frame
    ey = m.y + r * np.sin(th)
    half = 0.5 * ring.fov
    out = np.empty((s_n, k_n))
    step = max(1, CHUNK_CELLS // max(b_n * k_n, 1))
    for a in range(0, s_n, step):
        sl = slice(a, min(a + step, s_n))
        dx = ex[sl, :, None] - ring.x
        dy = ey[sl, :, None] - ring.y
        bearing = wrap_angle(np.arctan2(dy, dx) - ring.yaw)
        inside = valid[sl, :, None] & (np.abs(bearing) <= half)
        out[sl] = np.where(inside, np.hypot(dx, dy), np.inf).min(axis=1)
    reading = np.where(out < ring.max_range, out, ring.max_range)
    return np.where(out < ring.min_range, -np.inf, reading)


@dataclass(frozen=True)
class Emulation:
    """An emulated sonar log: the content to write, the per-scan readings and notes."""

    content: LogContent
    ranges: F64  # (S, K) readings of the emitted sonars
    ring: SonarRing  # the emitted sonars
    dropped: tuple[str, ...]  # sonars not emitted (outside the laser's view)
    notes: tuple[str, ...]
    truth: PoseBatch | None = None  # the true poses when the log's odometry is drifted

    def with_drift(self, model: DriftModel, seed: int) -> Emulation:
        """The same emulation with its odometry drifted by ``model`` (:mod:`pipeline.drift`,
        noise from ``PCG64(seed)``); the poses it started from become the truth."""
        if model.is_zero:
            return self
        p = self.content.poses
        rng = np.random.Generator(np.random.PCG64(seed))
        x, y, yaw = apply_drift(p.x, p.y, p.yaw, model.validate(), rng)
        drifted = PoseBatch(p.t_ns.copy(), x, y, yaw, p.parent_frame, p.child_frame)
        note = (
            f"odometry drifted: scale error {model.scale_error:g}, heading bias "
            f"{model.heading_bias_deg_per_m:g} deg/m, noise {model.noise_xy:g} m/√m and "
            f"{model.noise_yaw:g} rad/√rad{model.describe_random_walk()} (seed {seed}); the truth "
            "trajectory keeps the poses before drift"
        )
        return self._logging(drifted, note)


    def with_raw_odometry(self, odometry: PoseBatch) -> Emulation:
        """The same emulation with the robot's own wheel odometry as its pose track: real
        drift. The odometry is cut to the scans' time span (one pose either side) and moved
        rigidly to start at the first scan's pose, as :meth:`with_drift` starts at the true
        pose; the scan poses it replaces become the truth."""
        true = self.content.poses
        t0, t1 = int(true.t_ns[0]), int(true.t_ns[-1])
        t = odometry.t_ns
        if len(odometry) < 2 or t[0] > t0 or t[-1] < t1:
            raise InputError(
                f"the log's odometry ({_span_s(t)}) does not cover its scans ({_span_s(true.t_ns)})"
            )
        lo = int(np.searchsorted(t, t0, side="right")) - 1
        hi = int(np.searchsorted(t, t1, side="left")) + 1
        # The rigid motion taking the odometry's pose at the first scan onto the true one.
        motion = compose([true.x[0], true.y[0], true.yaw[0]], inverse(_pose_at(odometry, t0)))
        sl = slice(lo, hi)
        x, y, yaw = compose(motion, np.column_stack(
            [odometry.x[sl], odometry.y[sl], odometry.yaw[sl]])).T
        moved = PoseBatch(t[sl].copy(), x.copy(), y.copy(), yaw.copy(), odometry.parent_frame,
                          true.child_frame)
        ex, ey, _ = _pose_at(moved, true.t_ns)
        off = np.hypot(ex - true.x, ey - true.y)
        note = (
            f"poses: the log's raw wheel odometry ({hi - lo} poses, moved rigidly to start at "
            f"the first scan's pose), {float(off.mean()):.2f} m from the corrected scan poses "
            f"on average, {float(off.max()):.2f} m at most; the truth trajectory keeps the "
            "corrected poses"
        )
        return self._logging(moved, note)

    def _logging(self, odometry: PoseBatch, note: str) -> Emulation:
        """This emulation logging ``odometry`` as its poses; the poses it had become the
        truth trajectory."""
        return dataclasses.replace(
            self, content=dataclasses.replace(self.content, poses=odometry),
            truth=self.content.poses, notes=(*self.notes, note),
        )


def _pose_at(poses: PoseBatch, t_ns: int | I64) -> tuple[F64, F64, F64]:
    """Poses at stamps inside the batch's span: linear in x, y and in the unwrapped yaw."""
    t = (poses.t_ns - poses.t_ns[0]).astype(np.float64)
    q = (np.asarray(t_ns, dtype=np.int64) - poses.t_ns[0]).astype(np.float64)
    yaw = np.interp(q, t, np.unwrap(poses.yaw))
    return np.interp(q, t, poses.x), np.interp(q, t, poses.y), wrap_angle(yaw)


def _span_s(t_ns: I64) -> str:
    """``a…b s`` of a stamp array."""
    return f"{t_ns[0] / 1e9:.3f}…{t_ns[-1] / 1e9:.3f} s"


def emulate(
    log: LaserLog,
    ring: SonarRing,
    *,
    require_full_cone: bool = False,
    physics: SonarPhysics | None = None,
    seed: int = 0,
) -> Emulation:
    """Emulate the ring's sonars the laser can see for over every scan of ``log``: with
    ``physics`` the realistic sonar (:mod:`pipeline.tools.sonar`, noise from
    ``PCG64(seed)``), without it the ideal one (the shortest laser return in the cone)."""
    if len(log) == 0:
        raise InputError("no laser scans to emulate from")
    view = laser_view(log)
    coverage, axis_in = cone_coverage(ring, log.laser_mount, view)
    keep = coverage >= 1.0 if require_full_cone else axis_in
    idx = np.nonzero(keep)[0]
    dropped = tuple(ring.names[i] for i in np.nonzero(~keep)[0].tolist())
    notes = list(log.notes)
    rule = "whole cone" if require_full_cone else "beam axis"
    notes.append(
        f"laser view {math.degrees(view[0]):.1f}…{math.degrees(view[1]):.1f}°; "
        f"emitted {len(idx)} of {len(ring)} sonars ({rule} inside the laser's view)"
        + (f"; not emitted: {', '.join(dropped)}" if dropped else "")
    )
    partial = [
        f"{ring.names[i]} {100 * (1 - coverage[i]):.0f}%" for i in idx.tolist() if coverage[i] < 1.0
    ]
    if partial:
        notes.append(
            "cone outside the laser's view (readings there may be too long): " + ", ".join(partial)
        )
    if idx.size == 0:
        raise InputError("no sonar of the ring lies inside the laser's field of view; " + notes[-1])
    sub = ring.take(idx)
    if physics is None:
        ranges = emulate_ranges(log, sub)
    else:
        ranges, counts = scan_readings(log, sub, physics, seed)
        notes.append(
            f"realistic sonar (seed {seed}): {counts['ghost']} multipath ghosts, "
            f"{counts['missed']} missed echoes, {counts['crosstalk']} crosstalk readings"
        )
    s_n, k_n = ranges.shape
    t = np.repeat(log.t_ns, k_n)
    sid = np.tile(np.arange(k_n, dtype=np.int32), s_n)
    batch = make_range_batch(
        t,
        sid,
        ranges.reshape(-1),
        sub.fov[sid],
        sub.min_range[sid],
        sub.max_range[sid],
        scan_id=np.repeat(np.arange(s_n, dtype=np.int64), k_n),
    )
    poses = PoseBatch(
        log.t_ns.copy(),
        log.x.copy(),
        log.y.copy(),
        log.yaw.copy(),
        parent_frame=log.parent_frame,
        child_frame=log.child_frame,
    )
    mounts = {
        n: SensorMount(float(sub.x[i]), float(sub.y[i]), float(sub.yaw[i]))
        for i, n in enumerate(sub.names)
    }
    echo = ranges[np.isfinite(ranges) & (ranges < sub.max_range)]
    notes.append(
        f"{ranges.size} readings: {echo.size} echoes, "
        f"{int(np.count_nonzero(ranges >= sub.max_range))} at max range, "
        f"{int(np.count_nonzero(np.isneginf(ranges)))} too close (−inf)"
    )
    content = LogContent(batch, sub.names, poses, mounts)
    return Emulation(content, ranges, sub, dropped, tuple(notes))
