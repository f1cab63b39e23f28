"""Pose sync: the robot pose at each reading's own stamp, and the sonar's world geometry.

Between the two poses that bracket a reading's stamp the position is interpolated
linearly and the yaw along the shortest arc. A reading gets no pose — and is dropped and
counted by reason — before the first pose, after the last, or inside a gap between poses
longer than ``max_pose_gap_s``. ``time_offset_s`` is added to reading stamps first (for a
sensor whose clock is off).
"""

from __future__ import annotations

import mmap
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
_PATH_BLOCK = 65_536
_TRACK_BLOCK = 65_536  # poses per column block while the track is built (512 KB)
_TRACK_DTYPES = (np.int64, np.float64, np.float64, np.float64)  # t_ns, x, y, yaw


def _mapped_empty(n: int, dtype: type) -> np.ndarray:
    """An uninitialised array in its own anonymous memory mapping.

    The pose track is the one input kept whole for the length of a run. Taken from the
    malloc heap, its pieces sit between the readers' short-lived buffers and pin the heap
    (glibc raises its mmap threshold as large buffers are freed, so even MB-sized arrays
    end up there): measured, RSS grew twice as fast as the track. A mapping of its own
    is returned to the system as soon as the array goes.
    """
    size = max(n, 1) * np.dtype(dtype).itemsize
    return np.frombuffer(mmap.mmap(-1, size), dtype=dtype, count=n)
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
        # In blocks, so that hours of odometry make no full-length temporaries.
        total = 0.0
        for a in range(0, len(self) - 1, _PATH_BLOCK):
            b = min(a + _PATH_BLOCK + 1, len(self))
            total += float(np.hypot(np.diff(self.x[a:b]), np.diff(self.y[a:b])).sum())
        return total


def build_pose_track(batches: Sequence[PoseBatch]) -> PoseTrack:
    """One time-sorted track from the pose batches of one frame pair (see
    :class:`PoseTrackBuilder` for the filtering)."""
    builder = PoseTrackBuilder()
    for b in batches:
        builder.add(b)
    return builder.finish()


class PoseTrackBuilder:
    """Builds the pose track batch by batch, in log order (pass 1 of the ingest).

    Stamps that go backwards relative to the running maximum of all earlier stamps are
    dropped and counted; an exact duplicate of the previous kept stamp keeps its first pose;
    poses with a non-finite coordinate are dropped. Each batch is filtered as it arrives
    (the running maximum and the last kept stamp carry over) and its kept poses are copied
    into fixed blocks of ``_TRACK_BLOCK`` poses per column. :meth:`finish` joins the blocks
    one column at a time. Memory: about 40 bytes per kept pose at the peak, 32 after.
    Blocks and the joined columns live in their own memory mappings (see
    :func:`_mapped_empty`).
    """

    def __init__(self) -> None:
        self._cols: tuple[list[np.ndarray], ...] = ([], [], [], [])  # t, x, y, yaw blocks
        self._used = 0  # poses in the last block
        self._running: int | None = None  # the largest stamp so far
        self._last_kept: int | None = None  # the last stamp that passed the order filter
        self._frames = ("", "")
        self.backwards = 0
        self.duplicates = 0

    def add(self, b: PoseBatch) -> None:
        """Filter one batch and keep its poses."""
        n = len(b)
        if n == 0:
            return
        if self._running is None:
            self._frames = (b.parent_frame, b.child_frame)
        t = np.asarray(b.t_ns, dtype=np.int64)
        # A stamp below the running maximum of every stamp before it went backwards.
        before = np.empty(n, np.int64)
        before[0] = t[0] if self._running is None else self._running
        if n > 1:
            np.maximum.accumulate(t[:-1], out=before[1:])
            if self._running is not None:
                np.maximum(before[1:], self._running, out=before[1:])
        keep = t >= before
        self._running = int(max(before[-1], t[-1]))
        self.backwards += n - int(np.count_nonzero(keep))
        # Exact duplicates of the previous stamp kept by the order filter.
        idx = np.flatnonzero(keep)
        if idx.shape[0]:
            kt = t[idx]
            prev = np.empty_like(kt)
            prev[0] = kt[0] - 1 if self._last_kept is None else self._last_kept
            prev[1:] = kt[:-1]
            dup = kt == prev
            self.duplicates += int(np.count_nonzero(dup))
            keep[idx[dup]] = False
            self._last_kept = int(kt[-1])
        x = np.asarray(b.x, dtype=np.float64)
        y = np.asarray(b.y, dtype=np.float64)
        yaw = np.asarray(b.yaw, dtype=np.float64)
        keep &= np.isfinite(x) & np.isfinite(y) & np.isfinite(yaw)
        rows = np.flatnonzero(keep)
        while rows.shape[0]:
            if not self._cols[0] or self._used == _TRACK_BLOCK:
                for col, dtype in zip(self._cols, _TRACK_DTYPES, strict=True):
                    col.append(_mapped_empty(_TRACK_BLOCK, dtype))
                self._used = 0
            take = rows[: _TRACK_BLOCK - self._used]
            a, e = self._used, self._used + take.shape[0]
            for col, src in zip(self._cols, (t, x, y, yaw), strict=True):
                col[-1][a:e] = src[take]
            self._used = e
            rows = rows[take.shape[0]:]

    def finish(self) -> PoseTrack:
        """The track; the builder is emptied."""
        joined: list[np.ndarray] = []
        n = (len(self._cols[0]) - 1) * _TRACK_BLOCK + self._used if self._cols[0] else 0
        for col, dtype in zip(self._cols, _TRACK_DTYPES, strict=True):
            out = _mapped_empty(n, dtype)
            if col:
                col[-1] = col[-1][: self._used]
                np.concatenate(col, out=out)
            joined.append(out)
            col.clear()  # this column's blocks go before the next column is joined
        self._used = 0
        t, x, y, yaw = joined
        return PoseTrack(
            t.astype(np.int64, copy=False), x, y, yaw, *self._frames,
            backwards=self.backwards, duplicates=self.duplicates,
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
