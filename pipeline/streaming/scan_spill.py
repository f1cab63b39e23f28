"""The scans of the first mapping pass, spilled for the passes after it.

A multi-pass mapper reads the log's scans once per pass, in the same order. The first
pass builds them from the spilled readings (pose sync, scan building: :func:`~pipeline.run
.stream_scans`) and :class:`ScanSpill` appends each batch of scans it hands the mapper to
unlinked temporary files (:mod:`pipeline.streaming.spilled_columns`): the scans' columns,
each scan's length, and per batch its scan count and the readings streamed so far (for
progress). The later passes stream the same batches back (:meth:`SpilledScans.batches`):
the same values in the same scans and batches, so the mappers group, and add, exactly as
they would from the log, without pose sync and scan building again.

Memory stays flat with the log: the files live in the page cache or on disk, a walk holds
one batch (a copy, writable as built scans are) and gives the pages behind it back.
68 bytes a reading on disk (the nine columns of :class:`~pipeline.mapper.types.Scan`).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np

from pipeline.mapper.types import SCAN_FIELDS, Scan, ScanBatch
from pipeline.streaming.spilled_columns import ColumnSpill, MappedColumns

# Scan's columns and their dtypes (the pipeline's: pose sync builds them so).
_SCAN_DTYPES = {"t_ns": np.int64, "sensor_id": np.int32}
_DTYPES = tuple(np.dtype(_SCAN_DTYPES.get(name, np.float64)) for name in SCAN_FIELDS)


class ScanSpill:
    """Collects the batches of scans of a pass; :meth:`finish` maps them for reading."""

    def __init__(self) -> None:
        self._readings = ColumnSpill(_DTYPES, "sonarmap-scans-")
        self._scans = ColumnSpill((np.int64,), "sonarmap-scan-sizes-")
        self._batches = ColumnSpill((np.int64, np.int64), "sonarmap-scan-batches-")

    def add(self, scans: Sequence[Scan], readings_seen: int) -> None:
        """Append one batch of scans (in order) and the readings streamed so far."""
        if isinstance(scans, ScanBatch):  # joined already: its readings as they are
            if scans:
                self._readings.append(*(getattr(scans.cat, name) for name in SCAN_FIELDS))
                self._scans.append(np.diff(scans.bounds))
        elif scans:
            self._readings.append(*(
                np.concatenate([getattr(s, name) for s in scans]) for name in SCAN_FIELDS))
            self._scans.append([len(s) for s in scans])
        self._batches.append([len(scans)], [readings_seen])

    def finish(self) -> SpilledScans:
        """The spilled batches, mapped read-only."""
        return SpilledScans(self._readings.finish(), self._scans.finish(),
                            self._batches.finish())

    def close(self) -> None:
        """Drop the files without mapping them (the pass failed)."""
        for spill in (self._readings, self._scans, self._batches):
            spill.close()


class SpilledScans:
    """The batches of scans of a pass, in order."""

    def __init__(self, readings: MappedColumns, scans: MappedColumns,
                 batches: MappedColumns) -> None:
        self._readings = readings
        self._scans = scans
        self._batches = batches

    def __len__(self) -> int:
        """Scans spilled."""
        return len(self._scans)

    def batches(self) -> Iterator[tuple[ScanBatch, int]]:
        """Each batch's scans (a copy: writable, as built scans are) and the readings
        streamed up to it; the pages of the batches handed out are given back as the walk
        goes."""
        (sizes,) = self._scans.columns
        counts, seen = self._batches.columns
        cols = self._readings.columns
        scan = start = 0
        try:
            for k in range(len(self._batches)):
                n_scans = int(counts[k])
                bounds = np.zeros(n_scans + 1, dtype=np.int64)
                np.cumsum(sizes[scan:scan + n_scans], out=bounds[1:])
                n = int(bounds[-1])
                self._readings.release_before(start)
                cat = Scan(*[np.array(c[start:start + n]) for c in cols])
                yield ScanBatch(cat, bounds.tolist()), int(seen[k])
                scan += n_scans
                start += n
        finally:
            self._readings.release_before(None)
