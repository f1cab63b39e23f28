"""Ingest: the reader stream for the chosen topics, in two passes.

Pass 1 (:func:`survey`) reads poses and mounts and summarises the range stream (count,
time span, per-sensor counts and limits) without keeping the readings: it fixes the pose
track, the sensor table and the grid extent before any mapping starts. Pass 2
(:func:`ordered_ranges`) streams the readings again in time order for mapping. Memory is
bounded by the pose track (small) and one reorder window of readings, not the log length.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from formats.contract import LogReader, MountBatch, PoseBatch, RangeBatch, SensorMount
from pipeline.errors import InputError
from pipeline.pose_sync import PoseTrack, build_pose_track


@dataclass
class RangeSummary:
    """What pass 1 learns about the range stream."""

    count: int = 0
    t_min: int | None = None
    t_max: int | None = None
    per_sensor: dict[int, int] = field(default_factory=dict)
    max_range_m: float = float("nan")  # largest finite r_max any reading carries
    backwards: int = 0  # readings whose stamp is older than an earlier one of the same sensor

    def add(self, b: RangeBatch, last_t: dict[int, int]) -> None:
        n = len(b)
        if n == 0:
            return
        self.count += n
        lo, hi = int(b.t_ns.min()), int(b.t_ns.max())
        self.t_min = lo if self.t_min is None else min(self.t_min, lo)
        self.t_max = hi if self.t_max is None else max(self.t_max, hi)
        ids, counts = np.unique(b.sensor_id, return_counts=True)
        for i, c in zip(ids.tolist(), counts.tolist(), strict=True):
            self.per_sensor[i] = self.per_sensor.get(i, 0) + c
        finite = b.max_range_m[np.isfinite(b.max_range_m)]
        if finite.size:
            m = float(finite.max())
            self.max_range_m = m if np.isnan(self.max_range_m) else max(self.max_range_m, m)
        # Stamps going backwards per sensor (header stamps, REP: monotonic per frame).
        order = np.argsort(b.sensor_id, kind="stable")
        sid, t = b.sensor_id[order], b.t_ns[order]
        starts = np.flatnonzero(np.r_[True, sid[1:] != sid[:-1]])
        for k, s in enumerate(starts.tolist()):
            e = int(starts[k + 1]) if k + 1 < len(starts) else len(sid)
            key = int(sid[s])
            seg = t[s:e]
            prev = last_t.get(key)
            head = seg[:1] if prev is None else np.array([prev], dtype=np.int64)
            before = np.maximum.accumulate(np.r_[head, seg[:-1]])  # max of all earlier stamps
            self.backwards += int((seg < before).sum())
            run = np.maximum.accumulate(np.r_[head, seg])
            last_t[key] = int(run[-1])


@dataclass
class Survey:
    """Result of pass 1."""

    track: PoseTrack
    mounts: dict[str, SensorMount]
    ranges: RangeSummary
    sensor_names: list[str]


def survey(reader: LogReader) -> Survey:
    """Pass 1: pose track, static mounts and a summary of the readings."""
    poses: list[PoseBatch] = []
    mounts: dict[str, SensorMount] = {}
    summary = RangeSummary()
    last_t: dict[int, int] = {}
    for batch in reader.batches(("poses", "mounts", "ranges")):
        if isinstance(batch, RangeBatch):
            summary.add(batch, last_t)
        elif isinstance(batch, PoseBatch):
            if len(batch):
                poses.append(batch)
        elif isinstance(batch, MountBatch):
            mounts.update(batch.mounts)
    if summary.count == 0:
        raise InputError("the log has no range readings on the selected topics", reader.path)
    track = build_pose_track(poses)
    if len(track) < 2:
        raise InputError(
            f"the log has {len(track)} usable pose(s); mapping needs a pose stream", reader.path
        )
    return Survey(track, mounts, summary, list(reader.sensor_names))


def ordered_ranges(
    reader: LogReader, reorder_window_ns: int = 2_000_000_000
) -> Iterator[tuple[RangeBatch, int]]:
    """Pass 2: readings in time order, as ``(batch, late_count)`` chunks.

    Logs interleave topics and connections chunk by chunk, so batches are not globally
    sorted. Readings are held until the stream has moved ``reorder_window_ns`` past them,
    then released sorted (stable, so equal stamps keep log order). A reading older than
    what was already released is *late*: it is dropped and counted, since its scan has
    already been mapped.
    """
    pending: list[RangeBatch] = []
    released_up_to: int | None = None
    newest: int | None = None
    for batch in reader.batches(("ranges",)):
        if not isinstance(batch, RangeBatch) or len(batch) == 0:
            continue
        late = 0
        if released_up_to is not None:
            is_late = batch.t_ns < released_up_to
            late = int(is_late.sum())
            if late:
                batch = batch.take(~is_late)
        pending.append(batch)
        bmax = int(batch.t_ns.max()) if len(batch) else None
        if bmax is not None:
            newest = bmax if newest is None else max(newest, bmax)
        if newest is None:
            continue
        cut = newest - reorder_window_ns
        merged = RangeBatch.concat(pending)
        ready = merged.t_ns < cut
        if ready.any():
            out = merged.take(ready)
            pending = [merged.take(~ready)]
            order = np.argsort(out.t_ns, kind="stable")
            released_up_to = int(out.t_ns[order[-1]])
            yield out.take(order), late
        else:
            pending = [merged]
            if late:
                yield RangeBatch.concat([]), late
    if pending:
        merged = RangeBatch.concat(pending)
        if len(merged):
            order = np.argsort(merged.t_ns, kind="stable")
            yield merged.take(order), 0
