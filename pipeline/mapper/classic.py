"""The classic baseline (ALGORITHM.md §8): a log-odds grid with a sonar inverse sensor model.

Moravec & Elfes 1985 / Thrun et al. 2005 ch. 9. For each reading with an echo at range ``d``,
the cells of its cone (``|wrap(bearing − α)| ≤ β/2``) whose centre is at distance
``< d − w/2`` from the origin are free, those with ``|dist − d| ≤ w/2`` are occupied
(``w = classic_thickness_cells · resolution``). Max-range readings are ignored unless
``clear_on_max_range`` (then they free their cone up to ``r_max``). Log-odds update with
``logit(p_free)`` / ``logit(classic_p_occ)`` and the clamp of eq. 11.

Decisions: like the andersone free-space scan, updates are unions per scan — a cell gets at
most one update per scan; a cell both free (in one cone) and occupied (in another) in the
same scan gets the occupied update, as a hit in a point-cloud insertion overrides misses.
``probability`` is NaN where no update ever touched the cell; ``occupied = p > 0.5``.

The update runs as a compiled kernel (:mod:`pipeline.mapper.kernels.classic_scans`) over
groups of scans; ``reference=True`` runs the numpy code below, which states the rule and
which the tests compare the kernel with (the same cells and float32 values, bit for bit).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pipeline.config import MapperConfig
from pipeline.mapper.features_reference import empty_table
from pipeline.mapper.free_space import cone_spans, cone_table, free_radius
from pipeline.mapper.grid_raster import span_cells
from pipeline.mapper.kernels.classic_scans import classic_scans
from pipeline.mapper.occupancy import logit
from pipeline.mapper.reading_features import classify_scan, count_readings
from pipeline.mapper.scan_group import ScanGroup, scan_groups
from pipeline.mapper.types import F32, B, FeatureTable, GridSpec, MapperCounters, MapSnapshot, Scan
from pipeline.stages import reading_quality as rq


class ClassicMapper:
    """Occupancy grid with an inverse sonar model; no features."""

    passes = 1

    def begin_pass(self, index: int) -> None:
        """One pass only: nothing to prepare."""

    def __init__(self, config: MapperConfig, grid: GridSpec, reference: bool = False) -> None:
        self.config = config
        self.grid = grid
        self.reference = reference
        self.counters = MapperCounters()
        self.logodds: F32 = np.zeros(grid.shape, dtype=np.float32)
        self.touched: B = np.zeros(grid.shape, dtype=np.bool_)
        self.thickness = config.classic_thickness_cells * grid.resolution
        self.l_free = np.float32(logit(config.p_free))
        self.l_occ = np.float32(logit(config.classic_p_occ))
        self.l_min = np.float32(logit(config.p_clamp_min))
        self.l_max = np.float32(logit(config.p_clamp_max))

    def integrate(self, scan: Scan) -> None:
        """Add one scan: free and occupied cells of every cone, one update per cell."""
        self.integrate_many([scan])

    def integrate_many(self, scans: Sequence[Scan]) -> None:
        """Add scans in order (as :meth:`integrate` on each)."""
        if self.reference:
            for scan in scans:
                if self.config.classic_per_reading:
                    for k in range(len(scan)):
                        self._integrate_reference(scan.take(slice(k, k + 1)))
                    self.counters.scans -= len(scan) - 1  # still one scan
                else:
                    self._integrate_reference(scan)
            return
        for group in scan_groups(scans, self.config):
            self._integrate_group(group)

    def _integrate_group(self, group: ScanGroup) -> None:
        """The kernel over a group: classification and cone geometry by numpy for the group."""
        group.count(self.counters)
        cat, bounds, codes = group.cat, group.bounds, group.codes
        half_w = 0.5 * self.thickness
        outer = free_radius(cat, codes, self.config, margin=np.full(len(cat), -half_w))
        rows, cones, up_down = cone_table(cat, outer)
        if self.config.classic_per_reading:
            bounds = np.arange(len(cat) + 1, dtype=np.int64)  # every reading its own update
        g = self.grid
        self.counters.cells_freed += classic_scans(
            cones, up_down, cat.range_m[rows], codes[rows] == rq.OK,
            np.searchsorted(rows, bounds), half_w, g.origin_x, g.origin_y, g.resolution,
            g.width, g.height, self.l_free, self.l_occ, self.l_min, self.l_max, self.logodds,
            self.touched,
        )

    def _integrate_reference(self, scan: Scan) -> None:
        """The numpy reference of one scan's update."""
        codes = classify_scan(scan, self.config)
        count_readings(codes, self.counters)
        half_w = 0.5 * self.thickness
        ok = codes == rq.OK
        # Rasterise each cone out to its far edge (d + w/2, or r_max), classify by distance.
        outer = free_radius(scan, codes, self.config, margin=np.full(len(scan), -half_w))
        rows, spans = cone_spans(scan, outer, self.grid)
        owner, row, col = span_cells(spans)
        k = rows[owner]
        res, g = self.grid.resolution, self.grid
        dx = g.origin_x + (col + 0.5) * res - scan.origin_x[k]
        dy = g.origin_y + (row + 0.5) * res - scan.origin_y[k]
        dist = np.sqrt(dx * dx + dy * dy)  # as the kernel: sqrt is exact, hypot is slower
        d = scan.range_m[k]
        echo = ok[k]
        occ_cell = echo & (np.abs(dist - d) <= half_w)
        free_cell = np.where(echo, dist < d - half_w, True) & ~occ_cell
        if row.shape[0] == 0:
            return
        # One update per cell: mark the cones' bounding window, occupied wins over free.
        r0, c0 = int(row.min()), int(col.min())
        h, w = int(row.max()) - r0 + 1, int(col.max()) - c0 + 1
        local = (row - r0) * w + (col - c0)
        occ = np.zeros(h * w, dtype=np.bool_)
        occ[local[occ_cell]] = True
        free = np.zeros(h * w, dtype=np.bool_)
        free[local[free_cell]] = True
        free &= ~occ
        occ2, free2 = occ.reshape(h, w), free.reshape(h, w)
        lo = self.logodds[r0 : r0 + h, c0 : c0 + w]
        # np.minimum/np.maximum: np.clip's values at a fraction of its call cost.
        lo[free2] = np.minimum(np.maximum(lo[free2] + self.l_free, self.l_min), self.l_max)
        lo[occ2] = np.minimum(np.maximum(lo[occ2] + self.l_occ, self.l_min), self.l_max)
        self.touched[r0 : r0 + h, c0 : c0 + w] |= occ2 | free2
        n_free = int(np.count_nonzero(free))
        self.counters.cells_freed += n_free

    def snapshot(self) -> MapSnapshot:
        """Probability from the log-odds (NaN never touched); occupied = p > 0.5."""
        l64 = self.logodds.astype(np.float64)
        p = np.where(self.touched, 1.0 - 1.0 / (1.0 + np.exp(l64)), np.nan).astype(np.float32)
        with np.errstate(invalid="ignore"):
            occupied = p > 0.5
        return MapSnapshot(
            grid=self.grid,
            probability=p,
            free_logodds=self.logodds.copy(),
            occupied=occupied,
            observed=self.touched.copy(),
            features=empty_table(),
            counters=self.counters.as_dict(),
        )

    def feature_table(self) -> FeatureTable:
        """Always empty: the baseline keeps no features."""
        return empty_table()

    def feature_variance(self) -> tuple[float, float]:
        """(nan, nan): no features."""
        return (float("nan"), float("nan"))
