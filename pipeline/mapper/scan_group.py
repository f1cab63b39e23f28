"""Groups of scans prepared once for the compiled mappers: readings joined and classified.

The mappers' kernels loop over scans; what does not depend on the map state (the reading
classes, the free cones' geometry) numpy prepares for up to :data:`GROUP` scans at once. A
:class:`ScanGroup` computes each of these once, on first use, so the attribution method's
evidence pass and the paper's mapper it feeds share one classification and one cone table.
"""

from __future__ import annotations

import operator
from collections.abc import Iterator, Sequence
from functools import cached_property

import numpy as np
import numpy.typing as npt

from pipeline.config import MapperConfig
from pipeline.mapper.free_space import cone_table, free_radius
from pipeline.mapper.reading_features import classify_scan, count_readings
from pipeline.mapper.types import F64, I64, SCAN_FIELDS, B, MapperCounters, Scan, ScanBatch

# Scans prepared in one vectorised pass: enough to amortise the numpy call overhead, small
# enough to keep the pass's temporaries small (measured: 64 is as fast as 256, whose
# one-hour run peaked 25 MB higher with the numpy reference).
GROUP = 64
_SCAN_COLUMNS = operator.attrgetter(*SCAN_FIELDS)  # a scan's columns, in Scan's order


def concat_scans(scans: Sequence[Scan]) -> tuple[Scan, I64]:
    """The scans' readings as one Scan, and the row bounds: scan k is ``b[k]:b[k + 1]``
    (a :class:`~pipeline.mapper.types.ScanBatch` is joined already: no copy)."""
    if isinstance(scans, ScanBatch):
        return scans.cat, np.array(scans.bounds, dtype=np.int64)
    sizes = [len(s) for s in scans]
    bounds = np.zeros(len(scans) + 1, dtype=np.int64)
    np.cumsum(sizes, out=bounds[1:])
    if len(scans) == 1:
        return scans[0], bounds
    columns = zip(*map(_SCAN_COLUMNS, scans), strict=True)  # one C call per scan
    return Scan(*[np.concatenate(c) for c in columns]), bounds


def count_group(codes: npt.NDArray[np.int8], n_scans: int, counters: MapperCounters) -> None:
    """Add ``n_scans`` scans and their readings' classes ``codes`` to ``counters``."""
    count_readings(codes, counters)
    counters.scans += n_scans - 1  # count_readings counts one scan


class ScanGroup:
    """Consecutive scans as one Scan (``cat``; scan k is rows ``bounds[k]:bounds[k + 1]``)
    with their reading classes and, on first use, their free cones."""

    def __init__(self, scans: Sequence[Scan], config: MapperConfig) -> None:
        self.n_scans = len(scans)
        self.cat, self.bounds = concat_scans(scans)
        self.config = config
        self.codes: npt.NDArray[np.int8] = classify_scan(self.cat, config)

    def count(self, counters: MapperCounters) -> None:
        """Add the group's scans and readings (skipped ones by reason) to ``counters``."""
        count_group(self.codes, self.n_scans, counters)

    @cached_property
    def free_radius(self) -> F64:
        """Each reading's free range (§3), m; 0 where it clears nothing."""
        return free_radius(self.cat, self.codes, self.config)

    @cached_property
    def free_cones(self) -> tuple[I64, F64, B]:
        """The free cones as the compiled rasteriser takes them (:func:`cone_table`)."""
        return cone_table(self.cat, self.free_radius)


def scan_groups(scans: Sequence[Scan], config: MapperConfig,
                size: int = GROUP) -> Iterator[ScanGroup]:
    """The scans in order, ``size`` (:data:`GROUP`) at a time."""
    for g in range(0, len(scans), size):
        group = scans[g : g + size]
        if group:
            yield ScanGroup(group, config)
