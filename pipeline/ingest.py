"""Ingest: the reader stream for the chosen topics, in two passes.

Pass 1 (:func:`survey`) reads poses and mounts and summarises the range stream (count,
time span, per-sensor counts and limits) without keeping the readings: it fixes the pose
track, the sensor table and the grid extent before any mapping starts. Pass 2
(:func:`ordered_ranges`) streams the readings again in time order for mapping. Memory is
bounded by the pose track (small) and one reorder window of readings, not the log length.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np

from formats.arrays import I64, B
from formats.contract import LogReader, MountBatch, PoseBatch, RangeBatch, SensorMount
from formats.errors import InputError
from pipeline.pose_sync import PoseTrack, PoseTrackBuilder


@dataclass
class RangeSummary:
    """What pass 1 learns about the range stream."""

    count: int = 0
    t_min: int | None = None
    t_max: int | None = None
    per_sensor: dict[int, int] = field(default_factory=dict)
    max_range_m: float = float("nan")  # largest finite r_max any reading carries
    backwards: int = 0  # readings whose stamp is older than an earlier one of the same sensor

    def add(self, b: RangeBatch, stamps: StampOrder) -> None:
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
        self.backwards += int(stamps.backwards(b).sum())


def stamps_behind(t: I64, newest: int | None) -> tuple[B, I64, int | None]:
    """The one meaning of "stamps going backwards": a stamp older than the running maximum
    of the stamps before it (``newest``: the maximum of earlier batches, None if none).

    Returns the mask of such stamps, how far each is behind (ns, 0 where it is not) and the
    running maximum after ``t``. One jump back followed by rising stamps that stay below
    the earlier maximum flags every one of them: they are all older than a stamp already
    seen.
    """
    if t.shape[0] == 0:
        return np.zeros(0, dtype=bool), np.zeros(0, dtype=np.int64), newest
    head = t[:1] if newest is None else np.array([newest], dtype=np.int64)
    before = np.maximum.accumulate(np.r_[head, t[:-1]])  # max of all earlier stamps
    behind = np.maximum(before - t, 0)
    return behind > 0, behind, int(max(before[-1], t[-1]))


class StampOrder:
    """Header stamps going backwards (:func:`stamps_behind`), per sensor, in log order.

    Both passes flag the same readings: pass 1 counts them and pass 2 drops them
    (``dropped.stamp_backwards`` in metrics.json); ``sonarmap validate`` reports the same
    count.
    """

    def __init__(self) -> None:
        self._last: dict[int, int] = {}

    def backwards(self, b: RangeBatch) -> B:
        """Mask of the batch's readings that went backwards; updates the per-sensor state."""
        return self.steps_back(b) > 0

    def steps_back(self, b: RangeBatch) -> I64:
        """How far (ns) each reading's stamp lies below the largest earlier stamp of its
        sensor (0 = not backwards); updates the per-sensor state. ``validate`` reports
        with the same rule the pipeline drops by."""
        out = np.zeros(len(b), dtype=np.int64)
        order = np.argsort(b.sensor_id, kind="stable")  # each sensor's readings in log order
        sid, t = b.sensor_id[order], b.t_ns[order]
        starts = np.flatnonzero(np.r_[True, sid[1:] != sid[:-1]])
        ends = np.r_[starts[1:], len(sid)]
        for s, e in zip(starts.tolist(), ends.tolist(), strict=True):
            key = int(sid[s])
            _, behind, newest = stamps_behind(t[s:e], self._last.get(key))
            out[order[s:e]] = behind
            if newest is not None:
                self._last[key] = newest
        return out


@dataclass
class Survey:
    """Result of pass 1."""

    track: PoseTrack
    mounts: dict[str, SensorMount]
    ranges: RangeSummary
    sensor_names: list[str]


def survey(reader: LogReader, on_readings: Callable[[int], None] | None = None) -> Survey:
    """Pass 1: pose track, static mounts and a summary of the readings. ``on_readings``:
    called with the number of readings found so far after each batch of them."""
    poses = PoseTrackBuilder()
    mounts: dict[str, SensorMount] = {}
    summary = RangeSummary()
    stamps = StampOrder()
    for batch in reader.batches(("poses", "mounts", "ranges")):
        if isinstance(batch, RangeBatch):
            summary.add(batch, stamps)
            if on_readings is not None:
                on_readings(summary.count)
        elif isinstance(batch, PoseBatch):
            poses.add(batch)
        elif isinstance(batch, MountBatch):
            mounts.update(batch.mounts)
    if summary.count == 0:
        raise InputError("the log has no range readings on the selected topics", reader.path)
    track = poses.finish()
    if len(track) < 2:
        raise InputError(
            f"the log has {len(track)} usable pose(s); mapping needs a pose stream", reader.path
        )
    return Survey(track, mounts, summary, list(reader.sensor_names))


@dataclass
class RangeChunk:
    """Time-ordered readings released by :func:`ordered_ranges`, with what was dropped
    on the way since the previous chunk."""

    batch: RangeBatch
    late: int = 0
    backwards: int = 0


def ordered_ranges(reader: LogReader, reorder_window_ns: int = 2_000_000_000) -> Iterator[RangeChunk]:
    """Pass 2: readings in time order, in chunks.

    Readings whose header stamp jumped backwards (see :class:`StampOrder`) are dropped and
    counted. Logs interleave topics and connections chunk by chunk, so batches are not
    globally sorted: readings are held until the stream has moved ``reorder_window_ns``
    past them, then released sorted (stable, so equal stamps keep log order). A reading
    older than what was already released is *late*: it is dropped and counted, since its
    scan has already been mapped.
    """
    stamps = StampOrder()
    pending: list[RangeBatch] = []
    released_up_to: int | None = None
    newest: int | None = None
    for batch in reader.batches(("ranges",)):
        if not isinstance(batch, RangeBatch) or len(batch) == 0:
            continue
        back = stamps.backwards(batch)
        backwards = int(back.sum())
        if backwards:
            batch = batch.take(~back)
        late = 0
        if released_up_to is not None and len(batch):
            is_late = batch.t_ns < released_up_to
            late = int(is_late.sum())
            if late:
                batch = batch.take(~is_late)
        if len(batch):
            pending.append(batch)
            bmax = int(batch.t_ns.max())
            newest = bmax if newest is None else max(newest, bmax)
        ready_chunk: RangeBatch | None = None
        if newest is not None and pending:
            merged = RangeBatch.concat(pending)
            ready = merged.t_ns < newest - reorder_window_ns
            if ready.any():
                out = merged.take(ready)
                pending = [merged.take(~ready)]
                order = np.argsort(out.t_ns, kind="stable")
                released_up_to = int(out.t_ns[order[-1]])
                ready_chunk = out.take(order)
            else:
                pending = [merged]
        if ready_chunk is not None or late or backwards:
            yield RangeChunk(ready_chunk if ready_chunk is not None else RangeBatch.concat([]),
                             late, backwards)
    if pending:
        merged = RangeBatch.concat(pending)
        if len(merged):
            yield RangeChunk(merged.take(np.argsort(merged.t_ns, kind="stable")))
