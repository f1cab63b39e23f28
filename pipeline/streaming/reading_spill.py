"""The time-ordered readings, decoded once in pass 1 and spilled for the mapping passes.

Pass 1 (:func:`pipeline.stages.ingest.survey`) reads and decodes the log once; its reorder window
releases the readings in time order, chunk by chunk, and :class:`ReadingSpill` appends
each chunk to unlinked temporary files (:mod:`pipeline.streaming.spilled_columns`, as the pose
track). Every later pass streams the same chunks from the read-only mapping
(:meth:`SpilledReadings.chunks`) instead of reading and decoding the log again: the same
readings in the same chunks with the same late and backwards counts, so scans, maps and
metrics are those of a direct read. The pages behind the walk are given back as it goes.

Only what mapping reads is kept, 52 bytes a reading (stamp, sensor, range, beam width,
limits, scan id). The record time and the variance, which only ``sonarmap validate``
reads, are not: the batches carry ``record_t_ns = t_ns`` and a NaN variance, as those of
a log without them.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from formats.contract import RangeBatch
from pipeline.streaming.reorder_window import RangeChunk
from pipeline.streaming.spilled_columns import ColumnSpill, MappedColumns

# Kept columns of RangeBatch and their dtypes (the contract's).
_READING_COLUMNS = (
    ("t_ns", np.int64),
    ("sensor_id", np.int32),
    ("range_m", np.float64),
    ("fov_rad", np.float64),
    ("min_range_m", np.float64),
    ("max_range_m", np.float64),
    ("scan_id", np.int64),
)
# One row per released chunk: its readings, and the late and backwards readings dropped
# since the chunk before.
_CHUNK_COLUMNS = (np.int64, np.int64, np.int64)


class ReadingSpill:
    """Collects the released chunks of pass 1; :meth:`finish` maps them for reading."""

    def __init__(self) -> None:
        self._readings = ColumnSpill([d for _, d in _READING_COLUMNS], "sonarmap-readings-")
        self._chunks = ColumnSpill(_CHUNK_COLUMNS, "sonarmap-chunks-")

    def add(self, chunk: RangeChunk) -> None:
        """Append one released chunk (readings and drop counts)."""
        b = chunk.batch
        self._readings.append(*(getattr(b, name) for name, _ in _READING_COLUMNS))
        self._chunks.append([len(b)], [chunk.late], [chunk.backwards])

    def finish(self) -> SpilledReadings:
        """The spilled chunks, mapped read-only."""
        return SpilledReadings(self._readings.finish(), self._chunks.finish())

    def close(self) -> None:
        """Drop the files (pass 1 failed)."""
        self._readings.close()
        self._chunks.close()


class SpilledReadings:
    """The readings of pass 1 in time order, as the chunks the reorder window released."""

    def __init__(self, readings: MappedColumns, chunks: MappedColumns) -> None:
        self._readings = readings
        self._chunks = chunks

    def __len__(self) -> int:
        """Readings kept (released by the reorder window)."""
        return len(self._readings)

    def chunks(self) -> Iterator[RangeChunk]:
        """The chunks in order, each batch a read-only view of the mapping; the pages of
        chunks already handed out are given back as the walk goes, and all at its end."""
        sizes, late, back = self._chunks.columns
        cols = self._readings.columns
        start = 0
        try:
            for k in range(len(self._chunks)):
                n, n_late, n_back = int(sizes[k]), int(late[k]), int(back[k])
                self._readings.release_before(start)
                part = [c[start : start + n] for c in cols]
                t, sid, rng, fov, lo, hi, scan = part
                batch = RangeBatch(t, sid, rng, fov, lo, hi, scan, t, np.full(n, np.nan))
                start += n
                yield RangeChunk(batch, n_late, n_back)
        finally:
            self._readings.release_before(None)
