"""Ingest: the reader stream for the chosen topics, decoded once.

Pass 1 (:func:`survey`) reads poses and mounts and summarises the range stream (count,
time span, per-sensor counts and limits): it fixes the pose track, the sensor table and
the grid extent before any mapping starts. With ``keep_readings`` it also puts the
readings in time order (:mod:`pipeline.streaming.reorder_window`) and spills them to disk
(:mod:`pipeline.streaming.reading_spill`), so the mapping passes stream them from there instead of
reading and decoding the log again. :func:`ordered_ranges` streams a log's readings in
time order straight from the reader (the same window, for callers without a survey).
Memory is bounded by one reorder window of readings; the pose track and the spilled
readings live in temporary files, mapped read-only.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np

from formats.arrays import I64, B
from formats.contract import LogReader, MountBatch, PoseBatch, RangeBatch, SensorMount
from formats.errors import InputError
from formats.stamps import stamps_behind
from pipeline.stages.pose_sync import PoseTrack, PoseTrackBuilder
from pipeline.streaming.reading_spill import ReadingSpill, SpilledReadings
from pipeline.streaming.reorder_window import REORDER_WINDOW_NS, RangeChunk, ReorderWindow


@dataclass
class RangeSummary:
    """What pass 1 learns about the range stream."""

    count: int = 0
    t_min: int | None = None
    t_max: int | None = None
    per_sensor: dict[int, int] = field(default_factory=dict)
    max_range_m: float = float("nan")  # largest finite r_max any reading carries
    # the same per sensor id (sensors whose readings carry one)
    max_range_by_sensor: dict[int, float] = field(default_factory=dict)
    backwards: int = 0  # readings whose stamp is older than an earlier one of the same sensor

    def add(self, b: RangeBatch, backwards: B) -> None:
        """Count a batch in; ``backwards``: its readings whose stamp went backwards."""
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
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(b.max_range_m) & (b.max_range_m > 0)  # <= 0: none (Range)
        if ok.any():
            m = float(b.max_range_m[ok].max())
            self.max_range_m = m if np.isnan(self.max_range_m) else max(self.max_range_m, m)
            sid, r = b.sensor_id[ok], b.max_range_m[ok]
            for i in np.unique(sid).tolist():
                v = float(r[sid == i].max())
                self.max_range_by_sensor[i] = max(v, self.max_range_by_sensor.get(i, v))
        self.backwards += int(backwards.sum())


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
    """Result of pass 1 (``readings``: the spilled readings, None when not kept)."""

    track: PoseTrack
    mounts: dict[str, SensorMount]
    ranges: RangeSummary
    sensor_names: list[str]
    readings: SpilledReadings | None = None

    def ordered_ranges(self, reader: LogReader) -> Iterator[RangeChunk]:
        """The readings in time order: from the spill when pass 1 kept them, else read
        again from ``reader`` (:func:`ordered_ranges`); the same chunks either way."""
        if self.readings is not None:
            return self.readings.chunks()
        return ordered_ranges(reader)


def survey(reader: LogReader, on_readings: Callable[[int], None] | None = None,
           *, keep_readings: bool = False) -> Survey:
    """Pass 1: pose track, static mounts and a summary of the readings; with
    ``keep_readings`` the readings in time order too, spilled to disk. ``on_readings``:
    called with the number of readings found so far after each batch of them."""
    poses = PoseTrackBuilder()
    mounts: dict[str, SensorMount] = {}
    summary = RangeSummary()
    stamps = StampOrder()
    window = ReorderWindow() if keep_readings else None
    spill = ReadingSpill() if keep_readings else None
    try:
        for batch in reader.batches(("poses", "mounts", "ranges")):
            if isinstance(batch, RangeBatch):
                if len(batch):
                    back = stamps.backwards(batch)
                    summary.add(batch, back)
                    if window is not None and spill is not None:
                        chunk = window.push(batch, back)
                        if chunk is not None:
                            spill.add(chunk)
                if on_readings is not None:
                    on_readings(summary.count)
            elif isinstance(batch, PoseBatch):
                poses.add(batch)
            elif isinstance(batch, MountBatch):
                mounts.update(batch.mounts)
        if window is not None and spill is not None:
            last = window.flush()
            if last is not None:
                spill.add(last)
    except BaseException:
        if spill is not None:
            spill.close()
        raise
    readings = spill.finish() if spill is not None else None
    if summary.count == 0:
        raise InputError("the log has no range readings on the selected topics", reader.path)
    track = poses.finish()
    if len(track) < 2:
        raise InputError(
            f"the log has {len(track)} usable pose(s); mapping needs a pose stream", reader.path
        )
    return Survey(track, mounts, summary, list(reader.sensor_names), readings)


def ordered_ranges(reader: LogReader,
                   reorder_window_ns: int = REORDER_WINDOW_NS) -> Iterator[RangeChunk]:
    """The log's readings in time order, in chunks, read from ``reader``.

    Readings whose header stamp jumped backwards (see :class:`StampOrder`) are dropped and
    counted, then the reorder window (:class:`~pipeline.streaming.reorder_window.ReorderWindow`)
    releases them sorted and drops (and counts) the late ones.
    """
    stamps = StampOrder()
    window = ReorderWindow(reorder_window_ns)
    for batch in reader.batches(("ranges",)):
        if not isinstance(batch, RangeBatch) or len(batch) == 0:
            continue
        chunk = window.push(batch, stamps.backwards(batch))
        if chunk is not None:
            yield chunk
    last = window.flush()
    if last is not None:
        yield last
