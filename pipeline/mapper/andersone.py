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

from collections.abc import Sequence
from dataclasses import fields

import numpy as np

from pipeline.config import MapperConfig
from pipeline.mapper.correction import correct_features
from pipeline.mapper.feature_set import FeatureSet
from pipeline.mapper.free_space import FreeSpaceScan, free_space_scan, free_space_scans
from pipeline.mapper.occupancy import FreeLayer, final_probability, occupied_layer
from pipeline.mapper.reading_features import classify_scan, count_readings, reading_features
from pipeline.mapper.types import I64, FeatureTable, GridSpec, MapperCounters, MapSnapshot, Scan

# Scans whose stateless work (classification, reading features, free-space rasters) is
# done in one vectorised pass by ``integrate_many``: enough to amortise the numpy call
# overhead, small enough to keep the pass's temporaries to ~15 MB (measured: 64 is as
# fast as 256, whose one-hour run peaked 25 MB higher).
_GROUP = 64


def concat_scans(scans: Sequence[Scan]) -> tuple[Scan, I64]:
    """The scans' readings as one Scan, and the row bounds: scan k is ``b[k]:b[k + 1]``."""
    sizes = [len(s) for s in scans]
    bounds = np.zeros(len(scans) + 1, dtype=np.int64)
    np.cumsum(sizes, out=bounds[1:])
    if len(scans) == 1:
        return scans[0], bounds
    cat = Scan(*(np.concatenate([getattr(s, f.name) for s in scans]) for f in fields(Scan)))
    return cat, bounds


class AndersoneMapper:
    """The paper's method on one grid; feed it scans with :meth:`integrate`."""

    passes = 1

    def begin_pass(self, index: int) -> None:
        """One pass only: nothing to prepare."""

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

    def integrate_many(self, scans: Sequence[Scan]) -> None:
        """Add scans in order; the same state as :meth:`integrate` on each, bit for bit.

        What does not depend on the map state (reading classes, reading features,
        free-space rasters) is computed for up to ``_GROUP`` scans in one vectorised pass;
        merge, correction and the free-layer update then run scan by scan.
        """
        for g in range(0, len(scans), _GROUP):
            self._integrate_group(scans[g : g + _GROUP])

    def _integrate_group(self, scans: Sequence[Scan]) -> None:
        if not scans:
            return
        cat, bounds = concat_scans(scans)
        codes = classify_scan(cat, self.config)
        count_readings(codes, self.counters)
        self.counters.scans += len(scans) - 1  # count_readings counted one scan
        feats = reading_features(cat, codes, self.config)
        fcut = np.searchsorted(feats.row, bounds).tolist()
        frees = free_space_scans(cat, bounds, codes, self.config, self.grid)
        fs, cfg, counters = self.features, self.config, self.counters
        for k, free in enumerate(frees):
            a, b = fcut[k], fcut[k + 1]
            if b > a:
                created, merged = fs.merge_readings(
                    feats.mean[a:b], feats.cov[a:b], feats.t_ns[a:b]
                )
                counters.features_created += created
                counters.features_merged += merged
            self.last_free_space = free
            if free.count == 0:
                continue
            if cfg.feature_correction:
                correct_features(fs, free, cfg, self.grid, self.rng, counters)
            self.free_layer.update_window(free.row0, free.col0, free.mask)
            counters.cells_freed += free.count

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
