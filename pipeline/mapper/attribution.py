"""The default method: echo attribution against the whole log's free-space evidence.

Offline, in two passes over the log's scans (docs/ALGORITHM.md §9):

1. **Evidence.** Every reading with an echo at range ``d`` counts one free observation in
   each cell of its cone closer than ``d − κ_free·σ_d(d)`` (per reading, not per scan), and
   one *arc* observation in each cell of its cone within ``d ± band`` (the range arc where
   the echo may have come from; ``band = max(attr_band_sigmas·σ_d(d), res/2)``). The same
   pass feeds the paper's mapper (:class:`~pipeline.mapper.andersone.AndersoneMapper`), so
   ``features.parquet`` and the paper's metric stay the paper's Gaussian features.
2. **Attribution.** An echo came from the *nearest* surface in its cone, somewhere on its
   arc. Arc cells that the whole log has seen free more than ``attr_candidate_ratio``
   times as often as arcs cover them cannot have produced it; the echo is spread over the
   ``n`` remaining candidates, ``1/n**attr_dilution`` each.

A cell is occupied when its attributed weight ``H`` beats its free count ``F`` in a linear
test, ``H > attr_free_weight·F + attr_threshold·median(H > 0)``: the second term puts the
threshold on the log's own evidence scale (a dense log attributes more weight to every
cell than a sparse one), so no threshold is tuned to one log's reading density. Cells not
occupied take the free layer's probability from their free count (eq. 11 per reading, with
its clamps); cells with no free observation are unknown.

Pass 0 shares each group of scans' classification and free cones with the paper's mapper
(:mod:`~pipeline.mapper.scan_group`) and counts cones and arcs per row span, not per cell
(row difference grids, summed once when pass 1 begins). With ``threads = 2`` the paper's
mapper runs on a second thread (:mod:`~pipeline.mapper.paper_thread`), with the same
results.

Memory is the three float32 evidence grids (and pass 0's two int32 difference grids) and
the paper's feature set: nothing grows with the log's length (the pipeline streams the
log once per pass).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pipeline.config import MapperConfig
from pipeline.mapper.andersone import AndersoneMapper
from pipeline.mapper.free_space import cone_table
from pipeline.mapper.kernels.attribution import (
    attribute_echoes,
    count_arcs,
    count_free,
    empty_grid,
    empty_span_counts,
    span_counts,
)
from pipeline.mapper.occupancy import logit
from pipeline.mapper.paper_thread import PaperThread
from pipeline.mapper.reading_features import distance_sigma
from pipeline.mapper.scan_group import GROUP, ScanGroup, scan_groups
from pipeline.mapper.types import (
    F32,
    F64,
    I32,
    B,
    FeatureTable,
    GridSpec,
    MapperCounters,
    MapSnapshot,
    Scan,
)
from pipeline.stages import reading_quality as rq


class AttributionMapper:
    """Two-pass echo attribution; feed every scan in pass 0, then again in pass 1."""

    passes = 2

    def __init__(self, config: MapperConfig, grid: GridSpec) -> None:
        self.config = config
        self.grid = grid
        self.paper = AndersoneMapper(config, grid)
        # The paper's mapper on a second thread (config.threads == 2), else inline.
        self._paper_thread = PaperThread(self.paper) if config.threads > 1 else None
        self._group_index = 0  # of the next group in the current pass
        self._unattributed = 0  # echoes pass 1 found no candidate cell for
        self.free: F32 = empty_grid(grid.shape)
        self.arcs: F32 = empty_grid(grid.shape)
        self.hits: F32 = empty_grid(grid.shape)
        # Pass 0 counts spans in row difference grids; begin_pass(1) sums them into
        # ``free`` and ``arcs``.
        self._free_diff: I32 | None = empty_span_counts(grid.shape)
        self._arc_diff: I32 | None = empty_span_counts(grid.shape)
        self.pass_index = 0

    def begin_pass(self, index: int) -> None:
        """Start pass ``index`` (0: evidence, 1: attribution) over the same scans."""
        if index not in (0, 1):
            raise ValueError(f"the attribution method has passes 0 and 1, not {index}")
        if index == 1:
            self._settle_counts()
        self.pass_index = index
        self._group_index = 0

    def _settle_counts(self) -> None:
        """Add pass 0's span counts to ``free`` and ``arcs`` (once)."""
        if self._free_diff is not None and self._arc_diff is not None:
            self.free += span_counts(self._free_diff)
            self.arcs += span_counts(self._arc_diff)
            self._free_diff = self._arc_diff = None

    def integrate(self, scan: Scan) -> None:
        """Add one scan to the current pass."""
        self.integrate_many([scan])

    def integrate_many(self, scans: Sequence[Scan]) -> None:
        """Add scans in order to the current pass."""
        for group in scan_groups(scans, self.config, self._group_size()):
            self._integrate_group(group)
            self._group_index += 1

    def _group_size(self) -> int:
        """Scans per group in the current pass (both passes feed the paper's mapper, which
        takes the groups by index: the same groups in both)."""
        return GROUP

    def _integrate_group(self, group: ScanGroup) -> None:
        g, cfg = self.grid, self.config
        thread = self._paper_thread
        if self.pass_index == 0:
            # The paper's mapper and the free counts share the group's classes and cones:
            # preparing the group for the paper's mapper counts its free cones too.
            assert self._free_diff is not None
            if thread is None:
                self.paper.integrate_group(group, self._free_diff)
            elif not thread.offer(self._group_index, group, self._free_diff):
                _, cones, up_down = group.free_cones
                count_free(cones, up_down, g.origin_x, g.origin_y, g.resolution,
                           self._free_diff)
        elif thread is not None:
            thread.give(self._group_index, group)  # the groups pass 0 could not hand over
        cat = group.cat
        d: F64 = np.where(group.codes == rq.OK, cat.range_m, 0.0)
        band = np.maximum(cfg.attr_band_sigmas * distance_sigma(d, cfg), 0.5 * g.resolution)
        rows, arcs, up_down = cone_table(cat, np.where(d > 0.0, d + band, 0.0))
        r_inner = np.maximum(d - band, 0.0)[rows]
        if self.pass_index == 0:
            assert self._arc_diff is not None
            count_arcs(arcs, up_down, r_inner, g.origin_x, g.origin_y, g.resolution,
                       self._arc_diff)
        else:
            self._unattributed += int(attribute_echoes(
                arcs, up_down, r_inner, g.origin_x, g.origin_y, g.resolution, self.free,
                self.arcs, cfg.attr_candidate_ratio, cfg.attr_dilution, self.hits,
            ))

    @property
    def counters(self) -> MapperCounters:
        """The paper's mapper's counters (readings, scans, features) and the echoes pass 1
        left unattributed; waits for the paper's thread."""
        self._paper_done()
        self.paper.counters.echoes_unattributed = self._unattributed
        return self.paper.counters

    def _paper_done(self) -> None:
        """Wait for the paper's mapper's thread to integrate every group."""
        if self._paper_thread is not None:
            self._paper_thread.finish()

    def occupied(self) -> B:
        """Cells whose attributed echo weight beats their free count (the linear test)."""
        self._settle_counts()
        return self._linear_test(self.hits, self.free)

    def _linear_test(self, hits: F32, free: F32) -> B:
        """``hits > attr_free_weight · free + attr_threshold · median(hits > 0)``."""
        positive = hits[hits > 0]
        scale = float(np.median(positive)) if positive.size else 0.0
        threshold = self.config.attr_free_weight * free + self.config.attr_threshold * scale
        out: B = hits > threshold
        return out

    def snapshot(self) -> MapSnapshot:
        """Occupied cells at ``p_occ``; other observed cells from their free count."""
        cfg = self.config
        self._paper_done()
        occupied = self.occupied()
        lo, hi = logit(cfg.p_clamp_min), logit(cfg.p_clamp_max)
        free_logodds = np.clip(self.free * np.float32(logit(cfg.p_free)), lo, hi).astype(np.float32)
        seen_free = self.free > 0
        p = np.where(seen_free, 1.0 - 1.0 / (1.0 + np.exp(free_logodds.astype(np.float64))), np.nan)
        p[occupied] = cfg.p_occ
        return MapSnapshot(
            grid=self.grid,
            probability=p.astype(np.float32),
            free_logodds=free_logodds,
            occupied=occupied,
            observed=occupied | seen_free,
            features=self.paper.feature_table(),
            counters=self.counters.as_dict(),
        )

    def feature_table(self) -> FeatureTable:
        """The paper's features (pass 0), sorted by id."""
        self._paper_done()
        return self.paper.feature_table()

    def feature_variance(self) -> tuple[float, float]:
        """The paper's metric of the features (§7)."""
        self._paper_done()
        return self.paper.feature_variance()
