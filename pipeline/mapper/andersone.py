"""Andersone's probabilistic sonar mapper (ALGORITHM.md §1-5): features + free-space scans.

Per scan, in the order of §6: (1) the usable readings become Gaussian features (eqs. 1-4)
and are merged into the feature set (eqs. 5-8); (2) the scan's free-space scan is
rasterised (§3); (3) if ``feature_correction``, features touched by it are corrected with
particles (§4, eqs. 9-10); (4) the free layer is updated (eq. 11). The occupied layer and
the final map (eq. 12) are only computed by :meth:`AndersoneMapper.snapshot`.

Two implementations of the per-scan loop, with the same results bit for bit (the tests
compare them on random and real logs): the compiled kernels of
:mod:`pipeline.mapper.kernels` (the default: merge, rasters, correction and layer updates
run per scan in machine code), and the numpy reference (``reference=True``:
:mod:`~pipeline.mapper.features_reference`, :mod:`~pipeline.mapper.free_space`,
:mod:`~pipeline.mapper.correction`), which states the method readably. Both prepare what
does not depend on the map state (reading classes, reading features, cone geometry) with
numpy, for groups of scans at once (:mod:`~pipeline.mapper.scan_group`). The compiled path
splits a group into its scan-local half — :meth:`~AndersoneMapper.prepare` (reading
features, each scan's free-space scan) and :meth:`~AndersoneMapper.add_free_space` (the free
layer's counts) — and :meth:`~AndersoneMapper.integrate_prepared` (merge and correction,
which depend on the map state), so the default method's feeding thread can do the first
while the paper's thread does the second (:mod:`~pipeline.mapper.paper_thread`).

The particle generator is ``np.random.Generator(np.random.PCG64(config.seed))``, drawn from
in scan order (the kernels draw the same numbers from its state with numpy's algorithms,
:mod:`~pipeline.mapper.kernels.normals`), so the same scans and configuration give the same
state, bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.config import MapperConfig
from pipeline.mapper.correction import correct_features
from pipeline.mapper.features import FeatureStore
from pipeline.mapper.features_reference import FeatureSet
from pipeline.mapper.free_space import free_space_scans
from pipeline.mapper.kernels import andersone_scans
from pipeline.mapper.kernels.ellipse import occupied_cells
from pipeline.mapper.kernels.free_unions import (
    NO_COUNTS,
    FreeUnions,
    add_free_unions,
    free_unions,
)
from pipeline.mapper.kernels.normals import pcg64_words, set_pcg64_words
from pipeline.mapper.occupancy import FreeLayer, final_probability, occupied_layer
from pipeline.mapper.reading_features import ReadingFeatures, reading_features
from pipeline.mapper.scan_group import ScanGroup, count_group, scan_groups
from pipeline.mapper.types import (
    I32,
    I64,
    B,
    FeatureTable,
    GridSpec,
    MapperCounters,
    MapSnapshot,
    Scan,
)

# The kernels' counters array, in its order (kernels.correction.CREATED..CELLS_FREED).
_KERNEL_COUNTERS = ("features_created", "features_merged", "features_corrected",
                    "features_deleted", "features_protected", "features_split", "cells_freed")


@dataclass(frozen=True)
class PreparedGroup:
    """A group's scan-local half (:meth:`AndersoneMapper.prepare`): what does not depend on
    the map state — reading features (``fcut``: scan k's are rows ``fcut[k]:fcut[k+1]``)
    and each scan's free-space scan; the readings' classes for the counters. Not the
    readings or cones themselves (a queue of prepared groups holds only this)."""

    codes: npt.NDArray[np.int8]
    n_scans: int
    feats: ReadingFeatures
    fcut: I64
    unions: FreeUnions


class AndersoneMapper:
    """The paper's method on one grid; feed it scans with :meth:`integrate_many`.

    ``reference=True`` runs the numpy reference instead of the compiled kernels (tests).
    """

    passes = 1

    def begin_pass(self, index: int) -> None:
        """One pass only: nothing to prepare."""

    def __init__(self, config: MapperConfig, grid: GridSpec, reference: bool = False) -> None:
        self.config = config
        self.grid = grid
        self.reference = reference
        self.counters = MapperCounters()
        self.features: FeatureSet | FeatureStore = (
            FeatureSet(grid, config.match_distance) if reference
            else FeatureStore(grid, config.match_distance)
        )
        self.free_layer = FreeLayer(grid, config.p_free, config.p_clamp_min, config.p_clamp_max)
        self.rng = np.random.Generator(np.random.PCG64(config.seed))

    def integrate(self, scan: Scan) -> None:
        """Add one scan (§6 order: merge, free-space scan, correction, free layer)."""
        self.integrate_many([scan])

    def integrate_many(self, scans: Sequence[Scan]) -> None:
        """Add scans in order; the same state as :meth:`integrate` on each, bit for bit."""
        for group in scan_groups(scans, self.config):
            self.integrate_group(group)

    def integrate_group(self, group: ScanGroup, free_diff: I32 = NO_COUNTS) -> None:
        """Add a group of scans in order (:mod:`~pipeline.mapper.scan_group`); ``free_diff``
        as :meth:`prepare`'s."""
        if self.reference:
            assert free_diff is NO_COUNTS, "the numpy reference counts no free cones"
            group.count(self.counters)
            cat, bounds, codes = group.cat, group.bounds, group.codes
            feats = reading_features(cat, codes, self.config)
            self._reference_group(cat, bounds, codes, feats, np.searchsorted(feats.row, bounds))
            return
        work = self.prepare(group, free_diff)
        self.add_free_space(work)
        self.integrate_prepared(work)

    def prepare(self, group: ScanGroup, free_diff: I32 = NO_COUNTS) -> PreparedGroup:
        """The group's scan-local half (compiled path); changes nothing, so any thread may
        prepare a group while another integrates earlier ones. A row difference grid
        ``free_diff`` (the attribution method's) also gets every free cone's cells once
        (:func:`~pipeline.mapper.kernels.attribution.count_free`, from the same spans)."""
        assert not self.reference, "the numpy reference integrates whole groups"
        g = self.grid
        feats = reading_features(group.cat, group.codes, self.config)
        rows, cones, up_down = group.free_cones
        unions = free_unions(cones, up_down, np.searchsorted(rows, group.bounds), g.origin_x,
                             g.origin_y, g.resolution, g.width, g.height, free_diff)
        return PreparedGroup(group.codes, group.n_scans, feats,
                             np.searchsorted(feats.row, group.bounds), unions)

    def add_free_space(self, work: PreparedGroup) -> None:
        """Eq. 11 for every scan of the group: integer counts, the same in any order, and
        read only by :meth:`snapshot`, so it may run beside :meth:`integrate_prepared`."""
        add_free_unions(self.free_layer.diff_for_rows(), work.unions)

    def integrate_prepared(self, work: PreparedGroup) -> None:
        """Merge and correct the group's scans in order (§6; the free layer is
        :meth:`add_free_space`'s): the part that depends on the map state."""
        cfg, g, feats = self.config, self.grid, work.feats
        count_group(work.codes, work.n_scans, self.counters)
        assert isinstance(self.features, FeatureStore)
        self.features.reserve(len(feats))
        counts = np.zeros(len(_KERNEL_COUNTERS), dtype=np.int64)
        pcg = pcg64_words(self.rng)  # the kernel draws on from the generator's state
        andersone_scans.integrate_scans(
            self.features.arrays, feats.mean, feats.cov, feats.t_ns, work.fcut, work.unions,
            g.origin_x, g.origin_y, g.resolution, g.width, g.height, cfg.match_distance,
            cfg.feature_correction, pcg, cfg.n_particles,
            cfg.keep_fraction * cfg.n_particles, cfg.protect_times,
            cfg.sigma_floor(g.resolution) ** 2, cfg.split_guard, cfg.refit_positions == "cell",
            counts,
        )
        set_pcg64_words(self.rng, pcg)
        for name, value in zip(_KERNEL_COUNTERS, counts.tolist(), strict=True):
            setattr(self.counters, name, getattr(self.counters, name) + value)

    def _reference_group(self, cat: Scan, bounds: I64, codes: np.ndarray,
                         feats: ReadingFeatures, fcut: I64) -> None:
        fs, cfg, counters = self.features, self.config, self.counters
        assert isinstance(fs, FeatureSet)
        frees = free_space_scans(cat, bounds, codes, cfg, self.grid)
        cut = fcut.tolist()
        for k, free in enumerate(frees):
            a, b = cut[k], cut[k + 1]
            if b > a:
                created, merged = fs.merge_readings(
                    feats.mean[a:b], feats.cov[a:b], feats.t_ns[a:b]
                )
                counters.features_created += created
                counters.features_merged += merged
            if free.count == 0:
                continue
            if cfg.feature_correction:
                correct_features(fs, free, cfg, self.grid, self.rng, counters)
            self.free_layer.update_window(free.row0, free.col0, free.mask)
            counters.cells_freed += free.count

    def occupied(self) -> B:
        """Eq. 12's occupied layer: cells in any live feature's 2σ ellipse (and mean cells)."""
        s = self.features.alive_slots()
        mean, cov = self.features.mean[s], self.features.cov[s]
        if self.reference:
            return occupied_layer(mean, cov, self.grid)
        g = self.grid
        occ = np.zeros(g.shape, dtype=np.bool_)
        occupied_cells(mean, cov, 2.0, g.origin_x, g.origin_y, g.resolution, g.width, g.height,
                       occ)
        return occ

    def snapshot(self) -> MapSnapshot:
        """The map now: eq. 12 probability (NaN unknown), both layers, features, counters."""
        occupied = self.occupied()
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
