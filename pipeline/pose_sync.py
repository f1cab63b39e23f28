"""Pose sync: the robot pose at each reading's own stamp, and the sonar's world geometry.

Between the two poses that bracket a reading's stamp the position is interpolated
linearly and the yaw along the shortest arc. A reading gets no pose — and is dropped and
counted by reason — before the first pose, after the last, or inside a gap between poses
longer than ``max_pose_gap_s``. ``time_offset_s`` is added to reading stamps first (for a
sensor whose clock is off).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from formats.contract import PoseBatch, SensorMount

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

# Reasons a reading has no pose (codes in PoseLookup.reason).
POSE_OK = 0
BEFORE_FIRST_POSE = 1
AFTER_LAST_POSE = 2
IN_POSE_GAP = 3
POSE_REASONS = {
    POSE_OK: "ok",
    BEFORE_FIRST_POSE: "before_first_pose",
    AFTER_LAST_POSE: "after_last_pose",
    IN_POSE_GAP: "in_pose_gap",
}


@dataclass(frozen=True)
class PoseTrack:
    """Robot poses sorted by time, stamps strictly increasing (metres, radians, ns)."""

    t_ns: I64
    x: F64
    y: F64
    yaw: F64
    parent_frame: str
    child_frame: str
    backwards: int = 0  # stamps that went backwards in the log (dropped)
    duplicates: int = 0  # repeated stamps (the first was kept)

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    def path_length(self) -> float:
        """Length of the driven path, m."""
        if len(self) < 2:
            return 0.0
        return float(np.hypot(np.diff(self.x), np.diff(self.y)).sum())


def build_pose_track(batches: Sequence[PoseBatch]) -> PoseTrack:
    """One time-sorted track from the pose batches of one frame pair.

    Stamps that go backwards relative to the running maximum are dropped and counted;
    exact duplicate stamps keep their first pose.
    """
    if not batches:
        empty = np.empty(0)
        return PoseTrack(np.empty(0, np.int64), empty, empty, empty, "", "")
    # Memory: one concatenated copy per column; the masks are combined into one before
    # any filtered copy is made (pose tracks are the one input kept whole).
    t = np.concatenate([b.t_ns for b in batches]).astype(np.int64, copy=False)
    # A stamp below the running maximum of the stamps before it went backwards.
    running = np.maximum.accumulate(t)
    keep = np.ones(t.shape, bool)
    keep[1:] = t[1:] >= running[:-1]
    del running
    backwards = int((~keep).sum())
    # Exact duplicates of the previous kept stamp keep their first pose.
    kept_t = t[keep]
    first = np.ones(kept_t.shape, bool)
    first[1:] = kept_t[1:] != kept_t[:-1]
    duplicates = int((~first).sum())
    keep[np.flatnonzero(keep)[~first]] = False
    del kept_t, first
    x = np.concatenate([b.x for b in batches]).astype(np.float64, copy=False)
    y = np.concatenate([b.y for b in batches]).astype(np.float64, copy=False)
    yaw = np.concatenate([b.yaw for b in batches]).astype(np.float64, copy=False)
    keep &= np.isfinite(x) & np.isfinite(y) & np.isfinite(yaw)
    t, x, y, yaw = t[keep], x[keep], y[keep], yaw[keep]
    return PoseTrack(
        t,
        x,
        y,
        yaw,
        batches[0].parent_frame,
        batches[0].child_frame,
        backwards=backwards,
        duplicates=duplicates,
    )


@dataclass(frozen=True)
class PoseLookup:
    """Interpolated robot poses at reading stamps; ``reason`` is POSE_OK where valid."""

    x: F64
    y: F64
    yaw: F64
    reason: npt.NDArray[np.int8]


def wrap_angle(a: npt.ArrayLike) -> F64:
    """Angles wrapped to [−π, π)."""
    return np.asarray((np.asarray(a, dtype=np.float64) + np.pi) % (2 * np.pi) - np.pi)


def interpolate_poses(track: PoseTrack, t_ns: I64, max_gap_ns: int) -> PoseLookup:
    """The robot pose at each stamp in ``t_ns`` (any order), vectorised."""
    n = t_ns.shape[0]
    reason = np.zeros(n, np.int8)
    out_x = np.full(n, np.nan)
    out_y = np.full(n, np.nan)
    out_yaw = np.full(n, np.nan)
    if len(track) == 0:
        reason[:] = BEFORE_FIRST_POSE
        return PoseLookup(out_x, out_y, out_yaw, reason)
    tt = track.t_ns
    hi = np.searchsorted(tt, t_ns, side="left")  # first pose with stamp >= t
    exact = (hi < len(tt)) & (tt[np.minimum(hi, len(tt) - 1)] == t_ns)
    before = (hi == 0) & ~exact
    after = hi >= len(tt)
    reason[before] = BEFORE_FIRST_POSE
    reason[after] = AFTER_LAST_POSE
    inside = ~before & ~after
    i1 = np.where(exact, hi, np.clip(hi, 1, len(tt) - 1))
    i0 = np.where(exact, hi, i1 - 1)
    gap = tt[i1] - tt[i0]
    reason[inside & ~exact & (gap > max_gap_ns)] = IN_POSE_GAP
    ok = reason == POSE_OK
    i0, i1 = i0[ok], i1[ok]
    span = (tt[i1] - tt[i0]).astype(np.float64)
    # Integer-ns differences keep full precision for 64-bit epoch stamps.
    w = np.divide(
        (t_ns[ok] - tt[i0]).astype(np.float64), span, out=np.zeros(span.shape), where=span > 0
    )
    out_x[ok] = track.x[i0] + w * (track.x[i1] - track.x[i0])
    out_y[ok] = track.y[i0] + w * (track.y[i1] - track.y[i0])
    dyaw = wrap_angle(track.yaw[i1] - track.yaw[i0])
    out_yaw[ok] = wrap_angle(track.yaw[i0] + w * dyaw)
    return PoseLookup(out_x, out_y, out_yaw, reason)


def sonar_geometry(
    x: F64, y: F64, yaw: F64, mount_x: F64, mount_y: F64, mount_yaw: F64
) -> tuple[F64, F64, F64]:
    """World origin ``o = (x, y) + R(φ)(sx, sy)`` and beam angle ``α = φ + sθ`` (§1)."""
    c, s = np.cos(yaw), np.sin(yaw)
    ox = x + c * mount_x - s * mount_y
    oy = y + s * mount_x + c * mount_y
    return ox, oy, wrap_angle(yaw + mount_yaw)


def mount_arrays(
    mounts: Sequence[SensorMount | None],
) -> tuple[F64, F64, F64, npt.NDArray[np.bool_]]:
    """Per-sensor-id mount arrays (x, y, yaw) and which sensors have a mount."""
    have = np.array([m is not None for m in mounts], dtype=bool)
    mx = np.array([m.x if m else np.nan for m in mounts], dtype=np.float64)
    my = np.array([m.y if m else np.nan for m in mounts], dtype=np.float64)
    myaw = np.array([m.yaw if m else np.nan for m in mounts], dtype=np.float64)
    return mx, my, myaw, have
