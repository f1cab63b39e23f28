"""Scan building (ALGORITHM.md §6): which readings share a free-space scan.

Logs do not say where a scan starts, so a policy decides, from ``[scans] policy``:

* ``time`` — consecutive windows of ``window_s`` counted from the first pose stamp;
* ``motion`` — a new scan once the robot has moved ``max_travel_m`` or turned
  ``max_turn_deg`` since the pose at which the current scan started;
* ``explicit`` — the log's own scan id (one message carrying a whole ring, or a CSV
  ``scan`` column).

Each reading keeps its own interpolated pose; the scan only groups readings. Readings
arrive in time order; a scan is a maximal run of readings with the same key, so a scan
split across two input chunks is carried over and emitted whole.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from formats.arrays import I64
from formats.errors import InputError
from pipeline.config import ScanConfig
from pipeline.mapper.types import SCAN_FIELDS, Scan, ScanBatch
from pipeline.stages.pose_sync import PoseTrack


def motion_boundaries(track: PoseTrack, max_travel_m: float, max_turn_rad: float) -> I64:
    """Stamps (ns) at which the motion policy starts a new scan.

    Sequential by nature (each scan starts where the last one ended), but a loop over
    poses only — poses are few compared with readings.
    """
    out: list[int] = []
    if len(track) == 0:
        return np.empty(0, np.int64)
    sx, sy, syaw = float(track.x[0]), float(track.y[0]), float(track.yaw[0])
    for blk in track.blocks():  # in blocks: hours of odometry make no long lists
        xs, ys, yaws = track.x[blk].tolist(), track.y[blk].tolist(), track.yaw[blk].tolist()
        for j in range(1 if blk.start == 0 else 0, len(xs)):
            dyaw = (yaws[j] - syaw + math.pi) % (2 * math.pi) - math.pi
            if math.hypot(xs[j] - sx, ys[j] - sy) > max_travel_m or abs(dyaw) > max_turn_rad:
                out.append(int(track.t_ns[blk.start + j]))
                sx, sy, syaw = xs[j], ys[j], yaws[j]
    return np.asarray(out, dtype=np.int64)


class ScanKeys:
    """Computes the scan key of each reading for the configured policy."""

    def __init__(self, config: ScanConfig, track: PoseTrack) -> None:
        self.policy = config.policy
        self.t0 = int(track.t_ns[0]) if len(track) else 0
        self.window_ns = max(1, round(config.window_s * 1e9))
        self.boundaries = (
            motion_boundaries(track, config.max_travel_m, math.radians(config.max_turn_deg))
            if config.policy == "motion"
            else np.empty(0, np.int64)
        )

    def keys(self, t_ns: I64, scan_id: I64) -> I64:
        if self.policy == "time":
            return np.asarray((t_ns - self.t0) // self.window_ns, dtype=np.int64)
        if self.policy == "motion":
            return np.searchsorted(self.boundaries, t_ns, side="right").astype(np.int64)
        if (scan_id < 0).any():
            raise InputError(
                "scan policy 'explicit' needs a scan id per reading, and this log has none "
                "(one message per ring, or a CSV 'scan' column); use policy 'time' or 'motion'"
            )
        return scan_id.astype(np.int64)


@dataclass
class _Rows:
    """Readings with world geometry, before they are cut into scans."""

    key: I64
    scan: Scan

    def take(self, idx: slice) -> _Rows:
        return _Rows(self.key[idx], self.scan.take(idx))

    @staticmethod
    def concat(a: _Rows, b: _Rows) -> _Rows:
        return _Rows(
            np.concatenate([a.key, b.key]),
            Scan(*[np.concatenate([getattr(a.scan, n), getattr(b.scan, n)]) for n in SCAN_FIELDS]),
        )


class ScanBuilder:
    """Cuts a time-ordered stream of readings into :class:`Scan` s."""

    def __init__(self, keys: ScanKeys) -> None:
        self._keys = keys
        self._carry: _Rows | None = None
        self.count = 0

    def push(self, scan_ids: I64, readings: Scan) -> Iterator[Scan]:
        """Add readings (already pose-synced); yield every scan that is complete."""
        yield from self.push_batch(scan_ids, readings)

    def push_batch(self, scan_ids: I64, readings: Scan) -> ScanBatch:
        """Add readings (already pose-synced); the scans that are complete, as one batch
        (views of the readings: no scan is copied; the mappers group a batch without
        joining its scans again)."""
        if len(readings) == 0:
            return ScanBatch(readings, [0])
        rows = _Rows(self._keys.keys(readings.t_ns, scan_ids), readings)
        if self._carry is not None:
            rows = _Rows.concat(self._carry, rows)
        starts = np.flatnonzero(np.r_[True, rows.key[1:] != rows.key[:-1]])
        # The last run may continue in the next chunk: keep it back.
        last = int(starts[-1])
        self.count += len(starts) - 1
        self._carry = rows.take(slice(last, None))
        return ScanBatch(rows.scan.take(slice(0, last)), starts.tolist())

    def flush(self) -> Iterator[Scan]:
        """Yield the last scan."""
        if self._carry is not None and len(self._carry.scan):
            self.count += 1
            yield self._carry.scan
        self._carry = None

