"""Andersone's probabilistic sonar mapper (ALGORITHM.md §1-5): features + free-space scans.

Per scan, in the order of §6: (1) the usable readings become Gaussian features (eqs. 1-4)
and are merged into the feature set (eqs. 5-8, :mod:`~pipeline.mapper.feature_set`);
(2) the scan's free-space scan is rasterised (§3); (3) if ``feature_correction``, features
touched by it are corrected with particles (§4, eqs. 9-10); (4) the free layer is updated
(eq. 11). The occupied layer and the final map (eq. 12) are only computed by
:meth:`AndersoneMapper.snapshot`.

The particle generator is ``np.random.Generator(np.random.PCG64(config.seed))``, drawn from
in scan order, so the same scans and configuration give the same state, bit for bit.
"""

from __future__ import annotations

import numpy as np

from pipeline.config import MapperConfig
from pipeline.mapper.correction import correct_features
from pipeline.mapper.feature_set import FeatureSet
from pipeline.mapper.free_space import FreeSpaceScan, free_space_scan
from pipeline.mapper.occupancy import FreeLayer, final_probability, occupied_layer
from pipeline.mapper.reading_features import classify_scan, count_readings, reading_features
from pipeline.mapper.types import FeatureTable, GridSpec, MapperCounters, MapSnapshot, Scan


class AndersoneMapper:
    """The paper's method on one grid; feed it scans with :meth:`integrate`."""

    def __init__(self, config: MapperConfig, grid: GridSpec) -> None:
        self.config = config
        self.grid = grid
        self.counters = MapperCounters()
        self.features = FeatureSet(grid, config.match_distance)
        self.free_layer = FreeLayer(grid, config.p_free, config.p_clamp_min, config.p_clamp_max)
        self.rng = np.random.Generator(np.random.PCG64(config.seed))
        self.last_free_space: FreeSpaceScan | None = None

    def integrate(self, scan: Scan) -> None:
        """Add one scan (§6 order: merge, free-space scan, correction, free layer)."""
        codes = classify_scan(scan, self.config)
        count_readings(codes, self.counters)
        feats = reading_features(scan, codes, self.config)
        if len(feats):
            created, merged = self.features.merge_readings(feats.mean, feats.cov, feats.t_ns)
            self.counters.features_created += created
            self.counters.features_merged += merged
        free = free_space_scan(scan, codes, self.config, self.grid)
        self.last_free_space = free
        if free.count == 0:
            return
        if self.config.feature_correction:
            correct_features(self.features, free, self.config, self.grid, self.rng, self.counters)
        self.free_layer.update_window(free.row0, free.col0, free.mask)
        self.counters.cells_freed += free.count

    def snapshot(self) -> MapSnapshot:
        """The map now: eq. 12 probability (NaN unknown), both layers, features, counters."""
        s = self.features.alive_slots()
        occupied = occupied_layer(self.features.mean[s], self.features.cov[s], self.grid)
        logodds = self.free_layer.logodds.copy()
        return MapSnapshot(
            grid=self.grid,
            probability=final_probability(occupied, logodds, self.config.p_occ),
            free_logodds=logodds,
            occupied=occupied,
            observed=occupied | (logodds != 0),
            features=self.features.table(),
            counters=self.counters.as_dict(),
        )

    def feature_table(self) -> FeatureTable:
        """Live features sorted by id."""
        return self.features.table()

    def feature_variance(self) -> tuple[float, float]:
        """§7: (mean trace(P)/2, mean largest eigenvalue), m²; (nan, nan) without features."""
        return self.features.variance()
