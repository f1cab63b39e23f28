"""Pose sync: the robot pose at each reading's own stamp, and the sonar's world geometry.

Between the two poses that bracket a reading's stamp the position is interpolated
linearly and the yaw along the shortest arc. A reading gets no pose — and is dropped and
counted by reason — before the first pose, after the last, inside a gap between poses
longer than the pose gap limit, or between two poses the robot cannot have moved between
(faster than MAX_POSE_SPEED_MPS: an odometry glitch). An isolated glitch pose, one the
robot can neither have reached nor left (:func:`pose_spikes`), is dropped from the track
first, so the readings around it keep their pose. ``time_offset_s`` is added to reading
stamps first (for a sensor whose clock is off).

The pose gap limit is ``[pose_sync] max_pose_gap_s`` when set, else it adapts to the log
(:func:`pose_gap_limit_s`): AUTO_GAP_FACTOR × the median pose interval, at least
AUTO_GAP_MIN_S and at most AUTO_GAP_MAX_S — so 1 Hz odometry (poses 0.9 s apart) gets
2.7 s and 10-50 Hz odometry keeps 0.5 s.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from formats.angles import wrap_angle
from formats.arrays import F64, I64
from formats.contract import PoseBatch
from formats.stamps import stamps_behind
from pipeline.streaming.spilled_columns import ColumnSpill, MappedColumns

# Reasons a reading has no pose (codes in PoseLookup.reason).
POSE_OK = 0
BEFORE_FIRST_POSE = 1
AFTER_LAST_POSE = 2
IN_POSE_GAP = 3
POSE_JUMP = 4
# Faster than any robot that maps with sonars: a step between two poses at a higher speed
# is an odometry glitch, not motion (m/s).
MAX_POSE_SPEED_MPS = 10.0
# Stamps of real odometry jitter: a driver stamps messages on arrival, a logger writes two
# odometry lines 1 ms apart (the Intel lab's CARMEN log: 8 % of its steps "move" 3-30 cm in
# 1 ms). A step is a jump only beyond MAX_POSE_SPEED_MPS over its interval plus this (s),
# so no step under 1 m is one; glitches are metres (the Intel log's 19.6 m spike).
STAMP_JITTER_S = 0.1
AUTO_GAP_FACTOR = 3.0  # automatic pose gap limit: this many median pose intervals ...
AUTO_GAP_MIN_S = 0.5  # ... but at least this (s; the limit before it adapted) ...
AUTO_GAP_MAX_S = 5.0  # ... and at most this (s): longer gaps are gaps at any pose rate
# Pose segments (split at glitches) holding less than this share of the poses are outliers
# when the grid extent is sized.
OUTLIER_SHARE = 0.01
_BLOCK = 65_536  # poses per block of PoseTrack.blocks
_TRACK_DTYPES = (np.int64, np.float64, np.float64, np.float64)  # t_ns, x, y, yaw
POSE_REASONS = {
    POSE_OK: "ok",
    BEFORE_FIRST_POSE: "before_first_pose",
    AFTER_LAST_POSE: "after_last_pose",
    IN_POSE_GAP: "in_pose_gap",
    POSE_JUMP: "pose_jump",
}


@dataclass(frozen=True)
class PoseTrack:
    """Robot poses sorted by time, stamps strictly increasing (metres, radians, ns).

    A track from :class:`PoseTrackBuilder` lives in temporary files mapped read-only
    (see there); its columns are ordinary read-only arrays to every reader of them, and
    :meth:`release_before` lets the time-ordered pass 2 give back the pages it is done with.
    """

    t_ns: I64
    x: F64
    y: F64
    yaw: F64
    parent_frame: str
    child_frame: str
    backwards: int = 0  # stamps that went backwards in the log (dropped)
    duplicates: int = 0  # repeated stamps (the first was kept)
    spikes: int = 0  # isolated glitch poses (pose_spikes, dropped)
    _spill: MappedColumns | None = field(default=None, repr=False, compare=False)

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    def path_length(self) -> float:
        """Length of the driven path, m."""
        if len(self) < 2:
            return 0.0
        total = 0.0
        for blk in self.blocks(overlap=1):
            total += float(np.hypot(np.diff(self.x[blk]), np.diff(self.y[blk])).sum())
        return total

    def bounds(self) -> tuple[float, float, float, float]:
        """``(x_min, y_min, x_max, y_max)`` of the poses, m (NaN without poses)."""
        if len(self) == 0:
            return (math.nan,) * 4
        lo = [math.inf, math.inf]
        hi = [-math.inf, -math.inf]
        for blk in self.blocks():
            for k, col in enumerate((self.x, self.y)):
                lo[k] = min(lo[k], float(col[blk].min()))
                hi[k] = max(hi[k], float(col[blk].max()))
        return (lo[0], lo[1], hi[0], hi[1])

    def median_interval_s(self) -> float:
        """Median time between consecutive poses, s (NaN with fewer than two poses)."""
        if len(self) < 2:
            return math.nan
        steps = [np.diff(self.t_ns[blk]) for blk in self.blocks(overlap=1)]
        return float(np.median(np.concatenate(steps))) / 1e9

    def bulk_bounds(self) -> tuple[tuple[float, float, float, float], int]:
        """``(x_min, y_min, x_max, y_max)`` of the poses without isolated outliers, and how
        many poses were left out.

        The track is cut wherever consecutive poses are further apart than the robot can
        travel at MAX_POSE_SPEED_MPS; pieces holding less than OUTLIER_SHARE of the poses
        (a glitch to 2 km and back, a short jump) are outliers unless they are the largest
        piece. A track without glitches gives :meth:`bounds` and 0.
        """
        n = len(self)
        if n == 0:
            return (math.nan,) * 4, 0
        pieces: list[list[float]] = []  # [count, x0, y0, x1, y1] per piece, in time order
        for blk in self.blocks(overlap=1):
            t, x, y = self.t_ns[blk], self.x[blk], self.y[blk]
            dt = np.diff(t).astype(np.float64) / 1e9
            jump = is_pose_jump(np.hypot(np.diff(x), np.diff(y)), dt)
            # Start of each piece in this block (the block's first pose continues the
            # previous block's last piece: it was that block's overlap pose).
            cuts = np.flatnonzero(jump) + 1
            starts = np.r_[0, cuts]
            ends = np.r_[cuts, len(t)]
            first = blk.start == 0
            for k, (a, b) in enumerate(zip(starts.tolist(), ends.tolist(), strict=True)):
                if not first and k == 0:
                    a += 1  # the overlap pose was counted in the previous block
                    if a >= b:
                        continue
                    piece = pieces[-1]
                else:
                    piece = [0, math.inf, math.inf, -math.inf, -math.inf]
                    pieces.append(piece)
                piece[0] += b - a
                piece[1] = min(piece[1], float(x[a:b].min()))
                piece[2] = min(piece[2], float(y[a:b].min()))
                piece[3] = max(piece[3], float(x[a:b].max()))
                piece[4] = max(piece[4], float(y[a:b].max()))
        largest = max(range(len(pieces)), key=lambda i: pieces[i][0])
        keep = [p for i, p in enumerate(pieces) if i == largest or p[0] >= OUTLIER_SHARE * n]
        left_out = n - int(sum(p[0] for p in keep))
        box = (min(p[1] for p in keep), min(p[2] for p in keep),
               max(p[3] for p in keep), max(p[4] for p in keep))
        return box, left_out

    def blocks(self, overlap: int = 0) -> Iterator[slice]:
        """The track in order as slices of ``_BLOCK`` poses, each reaching ``overlap`` poses
        into the next; the pages behind each block are released once it has been used,
        and all pages at the end, so a walk over hours of poses stays small."""
        n = len(self)
        for a in range(0, n, _BLOCK):
            b = min(a + _BLOCK + overlap, n)
            yield slice(a, b)
            self._release_index(b - overlap)
        self.release_before(None)

    def release_before(self, t_ns: int | None = None) -> None:
        """Give back the resident pages of poses older than the pose before ``t_ns`` (all
        pages with None). Only pages are dropped: the values stay readable (from the file)."""
        if self._spill is None:
            return
        if t_ns is None:
            self._spill.release_before(None)
            return
        self._release_index(max(int(np.searchsorted(self.t_ns, t_ns)) - 2, 0))

    def _release_index(self, i: int) -> None:
        """Give back the whole pages of every column that lie before pose ``i``."""
        if self._spill is not None:
            self._spill.release_before(i)


def build_pose_track(batches: Sequence[PoseBatch]) -> PoseTrack:
    """One time-sorted track from the pose batches of one frame pair (see
    :class:`PoseTrackBuilder` for the filtering)."""
    builder = PoseTrackBuilder()
    for b in batches:
        builder.add(b)
    return builder.finish()


class PoseTrackBuilder:
    """Builds the pose track batch by batch, in log order (pass 1 of the ingest).

    Stamps that go backwards (:func:`formats.stamps.stamps_behind`: below the running
    maximum of all earlier stamps) are dropped and counted; an exact duplicate of the
    previous kept stamp keeps its first pose; poses with a non-finite coordinate are
    dropped; an isolated glitch pose (:func:`pose_spikes`) is dropped and counted. Each
    batch is filtered as it arrives (the running maximum, the last kept stamp and the last
    two poses, beside which the next batch's first pose is judged, carry over).

    Memory: the kept poses (32 bytes each, 23 MB per ten hours of 20 Hz odometry) are
    written to four anonymous temporary files, one per column
    (:mod:`pipeline.streaming.spilled_columns`), and :meth:`finish` maps them read-only. Pass 2 reads
    the track in time order and releases the pages behind it
    (:meth:`PoseTrack.release_before`), so the resident part of the track does not grow
    with the log: the page cache holds the rest, and the files vanish with the process,
    even a killed one (they are unlinked from the start). Measured before, when the track
    was kept in memory: peak RSS 1.25-1.33× from a one-hour to a ten-hour log.
    """

    def __init__(self) -> None:
        self._spill = ColumnSpill(_TRACK_DTYPES, prefix="sonarmap-track-")
        self._running: int | None = None  # the largest stamp so far
        self._last_kept: int | None = None  # the last stamp that passed the order filter
        self._frames = ("", "")
        self.backwards = 0
        self.duplicates = 0
        self.spikes = 0
        # The last two poses past the filters above (stamps; x, y, yaw rows), a dropped spike
        # among them as pose_spikes sees it over the whole track: the last is not written
        # yet (its spike test needs the next pose), the one before it only stands beside it.
        self._held = np.empty((0, 3))
        self._held_t = np.empty(0, np.int64)

    def add(self, b: PoseBatch) -> None:
        """Filter one batch and keep its poses."""
        n = len(b)
        if n == 0:
            return
        if self._running is None:
            self._frames = (b.parent_frame, b.child_frame)
        t = np.asarray(b.t_ns, dtype=np.int64)
        behind, _, self._running = stamps_behind(t, self._running)
        keep = ~behind
        self.backwards += int(np.count_nonzero(behind))
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
        if np.any(keep):
            self._keep_unless_spike(t[keep], np.column_stack([x[keep], y[keep], yaw[keep]]))

    def _keep_unless_spike(self, t: I64, pose: F64) -> None:
        """Write the poses whose spike test is settled, spikes dropped; hold the last two."""
        written = max(len(self._held_t) - 1, 0)  # held poses already written (or dropped)
        t = np.concatenate([self._held_t, t])
        pose = np.concatenate([self._held, pose])
        spike = pose_spikes(t, pose[:, 0], pose[:, 1])
        out = np.zeros(t.shape[0], np.bool_)
        out[written:-1] = ~spike[written:-1]
        self.spikes += int(np.count_nonzero(spike[written:-1]))
        self._spill.append(t[out], pose[out, 0], pose[out, 1], pose[out, 2])
        self._held_t, self._held = t[-2:].copy(), pose[-2:].copy()

    def finish(self) -> PoseTrack:
        """The track (its columns mapped from the files); the files are closed."""
        if len(self._held_t):  # the last pose has no next one to be a spike beside
            self._spill.append(self._held_t[-1:], self._held[-1:, 0], self._held[-1:, 1],
                               self._held[-1:, 2])
        spill = self._spill.finish()
        t, x, y, yaw = spill.columns
        return PoseTrack(
            t, x, y, yaw, *self._frames,
            backwards=self.backwards, duplicates=self.duplicates, spikes=self.spikes,
            _spill=spill,
        )


@dataclass(frozen=True)
class PoseLookup:
    """Interpolated robot poses at reading stamps; ``reason`` is POSE_OK where valid."""

    x: F64
    y: F64
    yaw: F64
    reason: npt.NDArray[np.int8]


def pose_gap_limit_s(configured_s: float, median_interval_s: float) -> float:
    """The pose gap limit in effect: ``configured_s`` when > 0, else AUTO_GAP_FACTOR ×
    the median pose interval within [AUTO_GAP_MIN_S, AUTO_GAP_MAX_S]."""
    if configured_s > 0:
        return configured_s
    if not math.isfinite(median_interval_s):
        return AUTO_GAP_MIN_S
    return min(max(AUTO_GAP_FACTOR * median_interval_s, AUTO_GAP_MIN_S), AUTO_GAP_MAX_S)


def is_pose_jump(step_m: F64, dt_s: F64) -> npt.NDArray[np.bool_]:
    """Whether steps of ``step_m`` metres in ``dt_s`` seconds between consecutive poses are
    odometry glitches: further than MAX_POSE_SPEED_MPS covers in ``dt_s + STAMP_JITTER_S``."""
    with np.errstate(invalid="ignore"):
        return np.asarray(step_m > MAX_POSE_SPEED_MPS * (np.maximum(dt_s, 0.0) + STAMP_JITTER_S))


def pose_spikes(t_ns: I64, x: F64, y: F64) -> npt.NDArray[np.bool_]:
    """Which poses are isolated glitches: the steps into and out of the pose are both
    jumps (:func:`is_pose_jump`) while its two neighbours are not a jump apart. A robot
    cannot have been there; an odometry line stamped out of its place (the Intel lab's
    CARMEN log stamps one line 81.83 s among lines at 2604.11 s: 19.6 m away and back in
    a millisecond) is one. The first and last poses are never spikes."""
    n = t_ns.shape[0]
    out = np.zeros(n, np.bool_)
    if n < 3:
        return out
    t = t_ns.astype(np.float64) / 1e9
    jump = is_pose_jump(np.hypot(np.diff(x), np.diff(y)), np.diff(t))
    across = is_pose_jump(np.hypot(x[2:] - x[:-2], y[2:] - y[:-2]), t[2:] - t[:-2])
    out[1:-1] = jump[:-1] & jump[1:] & ~across
    return out


def interpolate_poses(track: PoseTrack, t_ns: I64, max_gap_ns: int) -> PoseLookup:
    """The robot pose at each stamp in ``t_ns`` (any order), vectorised; readings between
    two poses a step apart that :func:`is_pose_jump` calls a glitch get POSE_JUMP."""
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
    cand = np.flatnonzero((reason == POSE_OK) & ~exact)
    if cand.size:
        a, b = i0[cand], i1[cand]
        step = np.hypot(track.x[b] - track.x[a], track.y[b] - track.y[a])
        dt = (tt[b] - tt[a]).astype(np.float64) / 1e9
        reason[cand[is_pose_jump(step, dt)]] = POSE_JUMP
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

