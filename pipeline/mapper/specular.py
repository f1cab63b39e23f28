"""Echo attribution with specular surfaces (ALGORITHM.md §10; the default, §11, builds on it).

A sonar hears a smooth surface only near its normal: beyond the surface's critical angle
θc the pulse is reflected away, the surface is silent and the echo (if any) comes from
farther. So a ray that passes a surface obliquely says nothing against it, and cannot
reach what lies behind it. θc varies between surfaces: log-normal, median
``spec_critical_angle_deg``, spread ``spec_critical_spread``; ``visible(θ) = P(θc > θ)``.

Four passes over the log's scans, in the same order:

0. §9's evidence: free and arc counts per cell (and the paper's features).
1. §9's attribution → a first map; every echo arc also adds its bearing (a doubled angle)
   to the cells it covers. Pooled over ``spec_normal_radius_m``, the bearings give each
   cell a normal line ψ and a consistency q ∈ [0, 1] (their mean resultant length).
2. Free and arc counts again: free evidence of a ray at any cell is ``q·visible(θ) + (1 − q)·v̄`` (v̄ = the mean of
   ``visible`` over incidences: a surface of unknown orientation), and a ray stops at a
   cell the first map holds occupied when ``q·(1 − visible(θ)) > ½`` (a surface of known orientation that it
   meets obliquely). With ``spec_max_range_free`` readings with no echo add free evidence
   out to ``r_max`` the same way.
3. §9's attribution with these counts and the same stops; the map is §9's linear test.

With ``threads = 2`` pass 2 runs on two threads by row band, pipelined: a group's upper
band runs on the second thread beside the next group's preparation and stops and its own
lower band; the attributions of passes 1 and 3 run on the second thread, one group at a time
in order, beside the next group's preparation and stops (pass 3's lists the candidates of
a group's last readings on this thread first: :mod:`~pipeline.mapper.kernels.echo_lists`);
:mod:`~pipeline.mapper.work_share` sizes the parts (:mod:`~pipeline.mapper.row_bands`): the
same bytes. The grids are complete once the next pass begins or the map is taken. Pass 3
recomputes the stops of only the readings pass 2 found stopped (the same cones and table;
against ``later_surfaces`` when a method judges pass 3 against other surfaces).
Memory: §9's grids and seven more grids, the list of surfaces and per-group buffers;
nothing grows with the log (docs/PERFORMANCE.md).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from concurrent.futures import Future

import numpy as np
import numpy.typing as npt
from scipy.special import ndtr

from pipeline.config import MapperConfig
from pipeline.mapper.attribution import AttributionMapper
from pipeline.mapper.free_space import cone_table
from pipeline.mapper.kernels.attribution import empty_grid
from pipeline.mapper.kernels.echo_lists import echo_candidate_lists, spread_candidate_lists
from pipeline.mapper.kernels.specular import (
    TraceArgs,
    shadow_offsets,
    shadow_profiles,
    silent_candidates,
    trace_readings,
)
from pipeline.mapper.reading_features import distance_sigma
from pipeline.mapper.row_bands import RowBands, balanced_split
from pipeline.mapper.scan_group import GROUP, ScanGroup
from pipeline.mapper.types import F32, F64, B, GridSpec, MapperCounters, MapSnapshot
from pipeline.mapper.work_share import WorkShare
from pipeline.stages import reading_quality as rq

TABLE_STEP = math.radians(0.25)  # sampling of the visibility table, rad
COS_SAMPLES = 4097  # samples of the kernel's visibility table, uniform in cos θ
# Scans per group in passes 2 and 3 (the groups of passes 0 and 1 are the paper's mapper's).
LATE_GROUP = 4 * GROUP


# A split attribution's balance: this thread's own and listing seconds, its share, and
# the band thread's seconds (appended once it is done).
Balance = tuple[float, float, float, list[float]]


def visibility_table(median_deg: float, spread: float) -> F64:
    """``visible(θ) = P(θc > θ)`` for θ = 0, step, … just past π/2, θc log-normal."""
    theta = np.arange(0.0, 0.5 * math.pi + 2 * TABLE_STEP, TABLE_STEP)
    with np.errstate(divide="ignore"):
        z = (np.log(theta) - math.log(math.radians(median_deg))) / max(spread, 1e-9)
    out: F64 = 1.0 - ndtr(z)
    return out


def mean_visibility(table: F64) -> float:
    """v̄: ``visible`` averaged over incidences uniform in [0, π/2]."""
    return float(np.mean(table[: round(0.5 * math.pi / TABLE_STEP) + 1]))


def cos_table(table: F64) -> F64:
    """``visible`` at cos θ = 0, 1/(COS_SAMPLES − 1), … 1 (the kernel's table)."""
    theta = np.arccos(np.linspace(0.0, 1.0, COS_SAMPLES))
    out: F64 = np.interp(theta, np.arange(len(table)) * TABLE_STEP, table)
    return out


def box_sum(a: F32, radius: int) -> F64:
    """Sum of ``a`` over the (2·radius + 1)² box around each cell (zero outside)."""
    p = np.pad(a.astype(np.float64), radius)
    c = np.zeros((p.shape[0] + 1, p.shape[1] + 1))
    np.cumsum(np.cumsum(p, axis=0), axis=1, out=c[1:, 1:])
    k = 2 * radius + 1
    h, w = a.shape
    out: F64 = c[k:k + h, k:k + w] - c[0:h, k:k + w] - c[k:k + h, 0:w] + c[0:h, 0:w]
    return out


def normal_lines(arc_c: F32, arc_s: F32, arcs: F32, radius: int) -> tuple[F32, F32]:
    """Each cell's normal line ψ (rad) and its consistency q ∈ [0, 1] from the doubled
    bearings of the arcs covering the cells within ``radius`` cells."""
    c, s, n = box_sum(arc_c, radius), box_sum(arc_s, radius), box_sum(arcs, radius)
    psi = (0.5 * np.arctan2(s, c)).astype(np.float32)
    q = np.hypot(c, s) / np.maximum(n, 1.0)
    return psi, np.clip(np.where(n > 0, q, 0.0), 0.0, 1.0).astype(np.float32)


class SpecularMapper(AttributionMapper):
    """§9's two passes, then both again with the first map's surfaces (module doc)."""

    passes = 4

    def __init__(self, config: MapperConfig, grid: GridSpec) -> None:
        super().__init__(config, grid)
        self.table = visibility_table(config.spec_critical_angle_deg,
                                      config.spec_critical_spread)
        self.v_unknown = mean_visibility(self.table)
        self.cos_table = cos_table(self.table)
        self.arc_c: F32 = empty_grid(grid.shape)
        self.arc_s: F32 = empty_grid(grid.shape)
        self.occ_index, self.occ_cols = silent_candidates(
            np.zeros(grid.shape, dtype=bool), empty_grid(grid.shape))
        self.nx: F32 = empty_grid(grid.shape)
        self.ny: F32 = empty_grid(grid.shape)
        self.consistency: F32 = empty_grid(grid.shape)
        self.free2: F32 = empty_grid(grid.shape)
        self.arcs2: F32 = empty_grid(grid.shape)
        self.hits2: F32 = empty_grid(grid.shape)
        self._unattributed2 = 0
        self._bands = RowBands(config.threads)
        # Pass 2's shadows, group by group (bit-packed ``stopped``): pass 3 recomputes only
        # the readings pass 2 found stopped (module doc).
        self._shadowed: list[npt.NDArray[np.uint8]] = []
        # The surfaces and table pass 2's shadows were computed against (replaced, never
        # changed in place, by whoever changes them): pass 3 reuses the shadows only on them.
        self._shadow_basis: tuple[object, ...] = ()
        # The surfaces ``(nx, ny, consistency)`` pass 3 will judge against, set by a method
        # whose pass 2 judges against others: pass 2 then flags the readings these stop.
        self.later_surfaces: tuple[F32, F32, F32] | None = None
        # The attribution of the last group (passes 1 and 3), running on the band thread:
        # (its unattributed echoes, first attribution?, readings with no echo, and for a
        # split one this thread's own and listing seconds, its share and the band's).
        self._attributing: tuple[Future[int], bool, int, Balance | None] | None = None
        self._attribution_share = WorkShare()
        # The last group of the count pass (pass 2): its trace, split row, upper band on
        # the band thread (its thread CPU seconds) and this thread's own seconds before.
        self._tracing: tuple[Callable[[int, int], int], int, Future[float], float,
                             float] | None = None
        self._trace_share = WorkShare()

    def begin_pass(self, index: int) -> None:
        """Start pass ``index`` (module doc) over the same scans."""
        if index not in range(self.passes):
            raise ValueError(f"the specular method has passes 0 to 3, not {index}")
        self._attributed()
        if index == 1:
            self._settle_counts()
        if index == 2:
            self._find_surfaces()
            self._shadowed.clear()
        self.pass_index = index
        self._group_index = 0

    def _group_size(self) -> int:
        """Passes 2 and 3 feed no paper's mapper and add reading by reading, so their
        results do not depend on the groups: larger ones spend less per group."""
        return LATE_GROUP if self.pass_index >= 2 else GROUP

    def _find_surfaces(self) -> None:
        """The first map's occupied cells, their normal lines and consistency."""
        self._attributed()  # the first map's hits and bearings are complete
        surfaces = AttributionMapper.occupied(self)
        radius = max(0, round(self.config.spec_normal_radius_m / self.grid.resolution))
        psi, self.consistency = normal_lines(self.arc_c, self.arc_s, self.arcs, radius)
        self.nx, self.ny = np.cos(psi), np.sin(psi)
        self.occ_index, self.occ_cols = silent_candidates(surfaces, self.consistency)

    def _integrate_group(self, group: ScanGroup) -> None:
        if self.pass_index == 0:
            super()._integrate_group(group)
            return
        started = time.thread_time()
        if self.pass_index == 1 and self._paper_thread is not None:
            self._paper_thread.give(self._group_index, group)
        g, cfg = self.grid, self.config
        cat = group.cat
        d: F64 = np.where(group.codes == rq.OK, cat.range_m, 0.0)
        band = np.maximum(cfg.attr_band_sigmas * distance_sigma(d, cfg), 0.5 * g.resolution)
        outer: F64 = np.where(d > 0.0, d + band, 0.0)
        free_r: F64 = group.free_radius
        if self.pass_index >= 2 and cfg.spec_max_range_free:
            silent = (group.codes == rq.MAX_RANGE) & np.isfinite(cat.max_range)
            free_r = np.where(silent, cat.max_range - cfg.eps_max, free_r)
            outer = np.where(silent, free_r, outer)
        rows, cones, up_down = cone_table(cat, outer)
        r_inner = np.where(d > 0.0, np.maximum(d - band, 0.0), np.inf)[rows]
        half = np.minimum(0.5 * cat.fov[rows], 0.5 * math.pi - 1e-9)
        first = self.pass_index == 1
        attribute = self.pass_index != 2
        alpha = cat.alpha[rows]
        height = g.shape[0]
        # The silent surfaces' shadows, cone by cone (none before the first map's surfaces).
        offsets = shadow_offsets(cones, half, g.resolution)
        stops: F64 = np.empty(int(offsets[-1]))
        stopped: B = np.zeros(len(rows), dtype=bool)
        later = self.later_surfaces if self.pass_index == 2 else None
        nx2, ny2, cons2 = later if later is not None else (self.nx, self.ny, self.consistency)
        stopped2: B = np.zeros(len(rows), dtype=bool) if later is not None else stopped
        if self.occ_cols.size:
            # Pass 3's shadows are pass 2's (the same cones, surfaces and table): only the
            # readings pass 2 found stopped can be (an infinite inner radius skips a reading).
            r_look = r_inner if self.pass_index != 3 else np.where(
                self._was_shadowed(len(rows)), r_inner, np.inf)

            def shadows(lo: int, hi: int) -> int:
                return int(shadow_profiles(
                    cones, up_down, r_look, alpha, half, g.origin_x, g.origin_y,
                    g.resolution, self.occ_index, self.occ_cols, self.nx, self.ny,
                    self.consistency, self.cos_table, attribute, lo, hi, offsets, stops,
                    stopped, later is not None, nx2, ny2, cons2, stopped2,
                ))

            shadows(0, len(rows))  # on this thread, beside the band thread's work
            if self.pass_index == 2:
                self._shadowed.append(np.packbits(stopped2))
                self._shadow_basis = (nx2, ny2, cons2, self.cos_table)

        # The kernel's arguments taken now: the band thread holds arrays, not the mapper.
        args = TraceArgs(
            cones=cones, up_down=up_down, r_inner=r_inner, r_free=free_r[rows], alpha=alpha,
            half_fov=half, gx=g.origin_x, gy=g.origin_y, res=g.resolution, offsets=offsets,
            stops=stops, stopped_in=stopped, nx=self.nx, ny=self.ny, cons=self.consistency,
            table=self.cos_table, v_unknown=self.v_unknown, attribute=attribute,
            bearings=first, free_in=self.free if first else self.free2,
            arcs_in=self.arcs if first else self.arcs2, ratio=cfg.attr_candidate_ratio,
            dilution=cfg.attr_dilution, free_out=self.free2, arcs_out=self.arcs2,
            hits=self.hits if first else self.hits2, arc_c=self.arc_c, arc_s=self.arc_s,
        )

        def trace(row_lo: int, row_hi: int) -> int:
            return int(trace_readings(*args, row_lo, row_hi))

        if attribute:
            # One group's attribution at a time, in order, on the band thread: this group's
            # waits for the previous one's, and the next group's preparation and shadows
            # overlap it (the attribution writes only the hits and bearings).
            no_echo = 0 if first else int(np.count_nonzero(d[rows] <= 0.0))
            work, balance = lambda: trace(0, height), None
            if not first and self._bands.parallel:
                work, balance = self._split_attribution(args, len(rows), started)
            self._attributed()
            self._attributing = (self._bands.later(work), first, no_echo, balance)
        elif not self._bands.parallel:
            self._bands.run(trace, height, height)
        else:
            # Pipelined: this group's upper band runs on the band thread beside the next
            # group's preparation and shadows and this group's lower band, which this thread
            # runs then (_traced); WorkShare sizes the bands so that both finish together.
            own = time.thread_time() - started
            self._traced()
            split = balanced_split(cones, alpha, g.origin_y, g.resolution, height,
                                   self._trace_share.share)

            def upper() -> float:
                t = time.thread_time()
                trace(split, height)
                return time.thread_time() - t

            self._tracing = (trace, split, self._bands.later(upper), own,
                             self._trace_share.share)

    def _traced(self) -> None:
        """The count pass's last group handed over: its lower band here, then the end of
        its upper band on the band thread (each row's adds stay in group order)."""
        if self._tracing is None:
            return
        trace, split, upper, own, share = self._tracing
        self._tracing = None
        t = time.thread_time()
        try:
            trace(0, split)
        finally:
            theirs = upper.result()
        self._trace_share.update(own, time.thread_time() - t, theirs, share)

    def _split_attribution(self, args: TraceArgs, n: int,
                           started: float) -> tuple[Callable[[], int], Balance]:
        """Pass 3's attribution of a group split in two (no bearings): this thread lists
        the echo candidates of its last readings now, the band thread traces the first ones
        and spreads those lists after them (:mod:`~pipeline.mapper.kernels.echo_lists`);
        :class:`WorkShare` sizes the parts."""
        share = self._attribution_share.share
        cut = n - round(share * n)
        own = time.thread_time() - started
        a = args
        lists = echo_candidate_lists(a.cones, a.up_down, a.r_inner, a.alpha, a.half_fov, a.gx,
                                     a.gy, a.res, a.offsets, a.stops, a.stopped_in, a.free_in,
                                     a.arcs_in, a.ratio, cut, n)
        mine = time.thread_time() - started - own
        first = args.first(cut)
        seconds: list[float] = []

        def work() -> int:
            t = time.thread_time()
            lost = int(trace_readings(*first, 0, a.free_in.shape[0]))  # all rows
            lost += int(spread_candidate_lists(a.hits, *lists, a.dilution))
            seconds.append(time.thread_time() - t)
            return lost

        return work, (own, mine, share, seconds)

    def _attributed(self) -> None:
        """Finish the grid writes handed to the band thread (the count pass's last group,
        :meth:`_traced`); wait for the attribution of the last group handed to it and
        count its unattributed echoes (readings with no echo have no arc: not
        unattributed)."""
        self._traced()
        if self._attributing is None:
            return
        future, first, no_echo, balance = self._attributing
        self._attributing = None
        lost = future.result()
        if balance is not None:
            own, mine, share, seconds = balance
            self._attribution_share.update(own, mine, seconds[0], share)
        if first:
            self._unattributed += lost
        else:
            self._unattributed2 += lost - no_echo

    def _surfaces_now(self) -> tuple[object, ...]:
        """What a reading's shadows depend on besides its cone."""
        return (self.nx, self.ny, self.consistency, self.cos_table)

    def _was_shadowed(self, readings: int) -> B:
        """Pass 2's ``stopped`` of the current group (the same groups in passes 2 and 3);
        every reading when the surfaces or the table have changed since."""
        if any(a is not b for a, b in zip(self._shadow_basis, self._surfaces_now(),
                                          strict=False)):
            return np.ones(readings, dtype=bool)
        packed = self._shadowed[self._group_index]
        if packed.size != (readings + 7) // 8:
            raise RuntimeError(f"scan group {self._group_index} differs between passes 2 and 3")
        out: B = np.unpackbits(packed, count=readings).astype(bool)
        return out

    def occupied(self) -> B:
        """§9's linear test on the second attribution and the surface-aware free counts."""
        self._attributed()
        self._settle_counts()
        return self._linear_test(self.hits2, self.free2)

    @property
    def counters(self) -> MapperCounters:
        """§9's counters, with the echoes the second attribution left unattributed."""
        self._attributed()
        counters = AttributionMapper.counters.fget(self)  # type: ignore[attr-defined]
        counters.echoes_unattributed = self._unattributed2
        return counters

    def snapshot(self) -> MapSnapshot:
        """§9's snapshot with the surface-aware free counts."""
        self._attributed()
        self._bands.close()  # the passes are done
        first, self.free = self.free, self.free2
        try:
            return super().snapshot()
        finally:
            self.free = first
