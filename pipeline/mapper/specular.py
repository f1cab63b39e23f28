"""The default method: echo attribution with specular surfaces (ALGORITHM.md §10).

Draft; see the docs section for the model.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ndtr

from pipeline.config import MapperConfig
from pipeline.mapper.attribution import AttributionMapper
from pipeline.mapper.free_space import cone_table
from pipeline.mapper.kernels.attribution import empty_grid
from pipeline.mapper.kernels.specular import trace_readings
from pipeline.mapper.reading_features import distance_sigma
from pipeline.mapper.scan_group import ScanGroup
from pipeline.mapper.types import F32, F64, I32, B, GridSpec
from pipeline.stages import reading_quality as rq

TABLE_STEP = math.radians(0.25)


def survival_table(median_deg: float, spread: float) -> F64:
    """P(critical angle > θ) for θ = 0, step, … π/2 (log-normal critical angle)."""
    theta = np.arange(0.0, 0.5 * math.pi + 2 * TABLE_STEP, TABLE_STEP)
    with np.errstate(divide="ignore"):
        z = (np.log(theta) - math.log(math.radians(median_deg))) / max(spread, 1e-6)
    out: F64 = 1.0 - ndtr(z)
    return out


def box_sum(a: F32, radius: int) -> F32:
    """Sum of ``a`` over the (2r+1)² box around each cell (zero outside)."""
    if radius <= 0:
        return a.copy()
    p = np.pad(a.astype(np.float64), radius)
    c = np.cumsum(np.cumsum(p, axis=0), axis=1)
    c = np.pad(c, ((1, 0), (1, 0)))
    k = 2 * radius + 1
    h, w = a.shape
    s = c[k:k + h, k:k + w] - c[0:h, k:k + w] - c[k:k + h, 0:w] + c[0:h, 0:w]
    return s.astype(np.float32)


class SpecularMapper(AttributionMapper):
    """Four passes: §9's evidence and attribution, then both again with the map's surfaces."""

    passes = 4

    def __init__(self, config: MapperConfig, grid: GridSpec) -> None:
        super().__init__(config, grid)
        self.table = survival_table(config.spec_critical_angle_deg, config.spec_critical_spread)
        self.dir_c: F32 = empty_grid(grid.shape)
        self.dir_s: F32 = empty_grid(grid.shape)
        self.arc_c: F32 = empty_grid(grid.shape)
        self.arc_s: F32 = empty_grid(grid.shape)
        self.cons: F32 = empty_grid(grid.shape)
        self.occ: B = np.zeros(grid.shape, dtype=bool)
        self.occ_rows: I32 = np.zeros((grid.shape[0], grid.shape[1] + 1), dtype=np.int32)
        self.psi: F32 = empty_grid(grid.shape)
        self.free2: F32 = empty_grid(grid.shape)
        self.arcs2: F32 = empty_grid(grid.shape)
        self.hits2: F32 = empty_grid(grid.shape)

    def begin_pass(self, index: int) -> None:
        if index not in (0, 1, 2, 3):
            raise ValueError(f"the specular method has passes 0 to 3, not {index}")
        if index == 1:
            self._settle_counts()
        if index == 2:
            self._surfaces()
        self.pass_index = index
        self._group_index = 0

    def _surfaces(self) -> None:
        """The pass-1 map's occupied cells and their normal lines."""
        occ = AttributionMapper.occupied(self)
        r = max(0, round(self.config.spec_normal_radius_m / self.grid.resolution))
        src = self.config.spec_normal_source
        if src == "arcs":
            c, s, n = box_sum(self.arc_c, r), box_sum(self.arc_s, r), box_sum(self.arcs, r)
        else:
            c, s, n = box_sum(self.dir_c, r), box_sum(self.dir_s, r), box_sum(self.hits, r)
        self.psi = (0.5 * np.arctan2(s, c)).astype(np.float32)
        with np.errstate(invalid="ignore", divide="ignore"):
            cons = np.where(n > 0, np.hypot(c, s) / n, 0.0)
        mode = self.config.spec_consistency
        if mode == "one":
            cons = np.where(occ, 1.0, 0.0)
        self.cons = np.clip(cons, 0, 1).astype(np.float32)
        self.occ = occ
        rows = np.zeros((occ.shape[0], occ.shape[1] + 1), dtype=np.int32)
        np.cumsum(occ, axis=1, out=rows[:, 1:])
        self.occ_rows = rows

    def _integrate_group(self, group: ScanGroup) -> None:
        if self.pass_index == 0:
            super()._integrate_group(group)
            return
        if self._paper_thread is not None and self.pass_index == 1:
            self._paper_thread.give(self._group_index, group)
        g, cfg = self.grid, self.config
        cat = group.cat
        d: F64 = np.where(group.codes == rq.OK, cat.range_m, 0.0)
        band = np.maximum(cfg.attr_band_sigmas * distance_sigma(d, cfg), 0.5 * g.resolution)
        outer = np.where(d > 0.0, d + band, 0.0)
        free_r = group.free_radius
        if self.pass_index >= 2 and cfg.spec_max_range_free:
            nomax = group.codes == rq.MAX_RANGE
            free_r = np.where(nomax, cat.max_range - cfg.eps_max, free_r)
            outer = np.where(nomax, free_r, outer)
        rows, arcs, up_down = cone_table(cat, outer)
        r_inner = np.where(d > 0, np.maximum(d - band, 0.0), np.inf)[rows]
        r_free = free_r[rows]
        alpha = cat.alpha[rows]
        half = np.minimum(0.5 * cat.fov[rows], 0.5 * math.pi - 1e-9)
        if self.pass_index == 1:
            occ = np.zeros((1, 1), dtype=bool)
            self._unattributed += int(trace_readings(
                arcs, up_down, r_inner, r_free, alpha, half, g.origin_x, g.origin_y,
                g.resolution, np.zeros(g.shape, dtype=bool), np.zeros((g.shape[0], g.shape[1] + 1), np.int32),
                self.psi, self.cons, self.table, TABLE_STEP, True, self.arc_c, self.arc_s, 1.0, self.free, self.arcs,
                cfg.attr_candidate_ratio, cfg.attr_dilution, self.free2, self.arcs2,
                self.hits, self.dir_c, self.dir_s))
            del occ
        elif self.pass_index == 2:
            trace_readings(
                arcs, up_down, r_inner, r_free, alpha, half, g.origin_x, g.origin_y,
                g.resolution, self.occ, self.occ_rows, self.psi, self.cons, self.table, TABLE_STEP,
                False, self.arc_c, self.arc_s, cfg.spec_unknown_visibility, self.free, self.arcs, cfg.attr_candidate_ratio, cfg.attr_dilution,
                self.free2, self.arcs2, self.hits2, self.dir_c, self.dir_s)
        else:
            self._unattributed2 = getattr(self, "_unattributed2", 0) + int(trace_readings(
                arcs, up_down, r_inner, r_free, alpha, half, g.origin_x, g.origin_y,
                g.resolution, self.occ, self.occ_rows, self.psi, self.cons, self.table, TABLE_STEP,
                True, self.dir_c, self.dir_s, 1.0, self.free2, self.arcs2, cfg.attr_candidate_ratio, cfg.attr_dilution,
                self.free2, self.arcs2, self.hits2, self.dir_c, self.dir_s))

    def occupied(self) -> B:
        self._settle_counts()
        hits = self.hits2
        positive = hits[hits > 0]
        scale = float(np.median(positive)) if positive.size else 0.0
        threshold = self.config.attr_free_weight * self.free2 + self.config.attr_threshold * scale
        out: B = hits > threshold
        return out

    def snapshot(self):  # type: ignore[no-untyped-def]
        free, self.free = self.free, self.free2
        try:
            return super().snapshot()
        finally:
            self.free = free
