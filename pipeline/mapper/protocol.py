"""What every mapper offers the pipeline (attribution, the andersone method, the classic grid)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from pipeline.config import MapperConfig
from pipeline.mapper.types import FeatureTable, GridSpec, MapperCounters, MapSnapshot, Scan


class Mapper(Protocol):
    """A mapper fed scan by scan, no I/O.

    A mapper reads the log's scans ``passes`` times, in the same order each time;
    ``begin_pass(k)`` announces pass ``k`` (0 first). One-pass mappers ignore it.
    """

    config: MapperConfig
    grid: GridSpec
    passes: int

    @property
    def counters(self) -> MapperCounters:
        """What happened inside the mapper (complete once the last pass is done)."""
        ...

    def begin_pass(self, index: int) -> None:
        """Start pass ``index`` over the scans."""
        ...

    def integrate(self, scan: Scan) -> None:
        """Add one scan."""
        ...

    def integrate_many(self, scans: Sequence[Scan]) -> None:
        """Add scans in order (the same result as ``integrate`` on each, faster)."""
        ...

    def snapshot(self) -> MapSnapshot:
        """The map as it stands."""
        ...

    def feature_table(self) -> FeatureTable:
        """The feature set sorted by id (empty for mappers without features)."""
        ...

    def feature_variance(self) -> tuple[float, float]:
        """(mean trace(P)/2, mean largest eigenvalue), m²; (nan, nan) without features."""
        ...
