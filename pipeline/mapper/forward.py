"""§10 with the sensor's detection model measured on the log (ALGORITHM.md §11).

§10 weighs a ray's free evidence at a cell by the chance that a surface there would have
answered: ``visible(θ)`` where the cell's orientation is known (consistency q), ``v̄``
where it is not, ``q·visible(θ) + (1 − q)·v̄``, and stops a ray at a surface when
``q·(1 − visible(θ)) > ½``. §10 takes both from a fixed critical-angle family (median 25°).
This method measures them with one E-step of a forward sensor model (Thrun 2003) against
§10's first map:

0. §9's evidence (free and arc counts, the paper's features).
1. §9's attribution → the first map; the arcs' bearings give each cell a normal line and a
   consistency q (§10).
2. Every reading traced through the first map: along each ray the first surface either
   answers or reflects the pulse away (nothing behind it is reached)
   (:func:`pipeline.mapper.kernels.forward.detection_counts`). Per incidence bin
   (:data:`INCIDENCE_BINS` over [0, 90°]): the reached surface cells of known orientation
   on the echo's arc and short of it give ``p(θ)``, the chance a surface met at θ answers
   (:func:`reach_detection`); per reading, the answered and passed bins give ``v̄``.
3. and 4. §10's passes 2 and 3 with ``visible(θ)`` = the evidence one pass at θ carries
   against a surface, relative to a head-on pass (:func:`pass_evidence`: the log-likelihood
   ratio ``ln(1 − p(θ)) / ln(1 − p(0))``), and ``v̄`` = the unknown-orientation bin's
   answered share with the coincidences taken out (:func:`unknown_rate`; the rate ``f``
   of an echo from elsewhere landing on a surface, from :func:`fit_detection`).

With ``wall_line_half_length_m > 0`` pass 0 also votes every echo's tangent lines and pass 3
judges passes near the wall lines found (:mod:`pipeline.mapper.wall_lines`) against the
line's normal (consistency 1); pass 4 keeps the cells' own normals (pass 3's shadows flag
the readings these stop: pass 4 recomputes only theirs).

Where the sonar hears surfaces at every incidence, ``p(θ) = p(0)``, every pass counts 1 and
no ray stops: §9's evidence (with max-range readings' free cones). No configuration key of
its own (the bins' smoothing is the uniform prior). Memory: §10's grids; the counts are 38
numbers. With ``threads = 2`` the E-step's readings are split between two threads, each
part counted into its own tables (integer counts: the sums do not depend on the split).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TypeVar

import numpy as np
from scipy.special import ndtr

from pipeline.config import MapperConfig
from pipeline.mapper.attribution import AttributionMapper
from pipeline.mapper.free_space import cone_table
from pipeline.mapper.kernels.forward import detection_counts
from pipeline.mapper.kernels.lines import vote_tangents
from pipeline.mapper.kernels.specular import cell_lists
from pipeline.mapper.reading_features import distance_sigma
from pipeline.mapper.scan_group import ScanGroup
from pipeline.mapper.specular import TABLE_STEP, SpecularMapper, cos_table
from pipeline.mapper.types import F32, F64, B, GridSpec
from pipeline.mapper.wall_lines import (
    NEAR_LINE_M,
    Votes,
    empty_votes,
    near_lines,
    wall_lines,
)
from pipeline.mapper.work_share import WorkShare
from pipeline.stages import reading_quality as rq

T = TypeVar("T")
INCIDENCE_BINS = 9  # equal bins of the detection curve over [0, 90°]
# Groups of E-step counts the worker thread may have pending (each holds its group's cones).
COUNT_BACKLOG = 2


def fitted_detection(stats: F64) -> F64:
    """``p_d`` per bin from the counts ``(answered, passed)``, Laplace smoothed."""
    out: F64 = (stats[0] + 1.0) / (stats[0] + stats[1] + 2.0)
    return out


# The grid the detection model is fitted on (module doc): head-on rate, critical-angle
# median (deg) and spread, and the rate of coincidences.
FIT_HEAD_ON = np.linspace(0.05, 1.0, 20)
FIT_MEDIAN_DEG = np.geomspace(1.0, 90.0, 96)
FIT_SPREAD = np.geomspace(0.1, 2.0, 14)
FIT_FLOOR = np.linspace(0.0, 0.5, 26)


def last_axis_sum(t: F64) -> F64:
    """``t.sum(axis=-1)`` (float64, C-contiguous), added as numpy's pairwise summation adds a
    row of 8 to 128 values: eight running sums combined in pairs, then the rest in order, onto
    0.0: the same bits, in a few whole-array adds instead of numpy's loop per row (the fit's
    rows are :data:`INCIDENCE_BINS` values)."""
    n = t.shape[-1]
    if not 8 <= n <= 128:
        out: F64 = t.sum(axis=-1)
        return out
    c = [t[..., k] for k in range(n)]
    r = c[:8]
    i = 8
    while i < n - n % 8:
        r = [r[k] + c[i + k] for k in range(8)]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    for k in range(i, n):
        res = res + c[k]
    total: F64 = 0.0 + res
    return total


def fit_detection(stats: F64) -> tuple[float, float, float, float]:
    """The detection model ``answered share(θ) = f + (1 − f)·p0·P(θc > θ)`` (θc log-normal:
    median, spread) fitted to the counts per incidence bin by maximum likelihood (binomial,
    on a grid: deterministic); returns ``(p0, median_deg, spread, f)``."""
    centres = (np.arange(INCIDENCE_BINS) + 0.5) * (90.0 / INCIDENCE_BINS)
    z = (np.log(centres)[None, None, :] - np.log(FIT_MEDIAN_DEG)[:, None, None]) / FIT_SPREAD[
        None, :, None]
    vis = 1.0 - ndtr(z)  # (median, spread, bin)
    a, n = stats[0, :INCIDENCE_BINS], stats[0, :INCIDENCE_BINS] + stats[1, :INCIDENCE_BINS]
    miss = n - a
    best = (-math.inf, 1.0, 90.0, 1.0, 0.0)
    # The binomial log-likelihood a·ln p + (n − a)·ln(1 − p) per bin, in place (the same
    # operations on the same values as the expression written out: the same bits).
    p, q = np.empty_like(vis), np.empty_like(vis)
    for f in FIT_FLOOR:
        for p0 in FIT_HEAD_ON:
            np.multiply((1.0 - f) * p0, vis, out=p)
            np.add(f, p, out=p)
            np.clip(p, 1e-6, 1.0 - 1e-6, out=p)
            np.log1p(np.negative(p, out=q), out=q)
            np.log(p, out=p)
            p *= a
            q *= miss
            p += q
            ll = last_axis_sum(p)
            k = int(np.argmax(ll))
            if ll.flat[k] > best[0]:
                i, j = np.unravel_index(k, ll.shape)
                best = (float(ll.flat[k]), float(p0), float(FIT_MEDIAN_DEG[i]),
                        float(FIT_SPREAD[j]), float(f))
    return best[1], best[2], best[3], best[4]


def unknown_rate(p_d: F64, floor: float) -> float:
    """``v̄``: the share of reaches a surface of unknown orientation answered, coincidences
    (``floor``) taken out."""
    return max(0.0, float(p_d[INCIDENCE_BINS]) - floor) / (1.0 - floor)


def reach_detection(reaches: F64) -> F64:
    """``p(θ)`` per oriented bin from the reached surface cells ``(on the arc, passed)``:
    each bin's share under the uniform prior (Laplace), then the closest curve that does not
    rise with incidence (a surface's backscatter falls off its normal), weighted by the
    bins' counts (pool adjacent violators; a bin with few reaches takes its neighbours')."""
    weight = reaches[0] + reaches[1] + 2.0
    share = (reaches[0] + 1.0) / weight
    blocks: list[list[float]] = []  # [mean, weight, bins]
    for v, w in zip(share.tolist(), weight.tolist(), strict=True):
        blocks.append([v, w, 1.0])
        while len(blocks) > 1 and blocks[-2][0] < blocks[-1][0]:
            v2, w2, n2 = blocks.pop()
            v1, w1, n1 = blocks.pop()
            blocks.append([(v1 * w1 + v2 * w2) / (w1 + w2), w1 + w2, n1 + n2])
    out: F64 = np.repeat([b[0] for b in blocks], [int(b[2]) for b in blocks])
    return out


def pass_evidence(p_d: F64) -> F64:
    """The evidence a ray passing a surface at each bin's incidence carries against it,
    relative to a head-on pass: the log-likelihood ratio ``ln(1 − p(θ))`` over the first
    bin's, in [0, 1] (1 where the surface answers as often as head-on, 0 where it never
    answers)."""
    out: F64 = np.clip(np.log1p(-p_d) / math.log1p(-float(p_d[0])), 0.0, 1.0)
    return out


def evidence_table(weights: F64) -> F64:
    """``weights`` (one per bin, at the bins' centres) on §10's θ grid (0, TABLE_STEP, …
    just past π/2), linear between the centres and constant beyond the first and last."""
    theta = np.arange(0.0, 0.5 * math.pi + 2 * TABLE_STEP, TABLE_STEP)
    centres = (np.arange(len(weights)) + 0.5) * (0.5 * math.pi / len(weights))
    out: F64 = np.interp(theta, centres, weights)
    return out


def _near_lines(votes: Votes, resolution: float, half_length_m: float) -> tuple[B, F32, F32]:
    """The cells within :data:`NEAR_LINE_M` of a wall line of pass 0's votes and the line's
    normal there (pass 3's surfaces near the lines)."""
    on, nx, ny = wall_lines(votes, resolution, half_length_m)
    return near_lines(on, nx, ny, NEAR_LINE_M / resolution)


def _on_own_thread(work: Callable[[], T]) -> Future[T]:
    """``work()`` on a thread of its own, which ends with it (numpy releases the GIL)."""
    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="sonarmap-lines")
    try:
        return pool.submit(work)
    finally:
        pool.shutdown(wait=False)


class ForwardMapper(SpecularMapper):
    """§10 with ``visible(θ)`` and ``v̄`` measured on the first map (module doc); five
    passes."""

    passes = 5

    def __init__(self, config: MapperConfig, grid: GridSpec) -> None:
        super().__init__(config, grid)
        self.stats: F64 = np.zeros((2, INCIDENCE_BINS + 1))
        self.reaches: F64 = np.zeros((2, INCIDENCE_BINS))
        self.p_d: F64 = fitted_detection(self.stats)
        self.p_reach: F64 = reach_detection(self.reaches)
        self.surfaces: B = np.zeros(grid.shape, dtype=bool)  # the first map
        self.surface_index, self.surface_cols = cell_lists(self.surfaces)
        self._measuring = False
        self._lines_on = config.wall_line_half_length_m > 0.0
        self.votes = empty_votes(grid if self._lines_on else GridSpec(0, 0, 1, 0, 0))
        self._own: tuple[F32, F32, F32] | None = None  # the cells' own normals (pass 3)
        # The wall lines near each cell (pass 3), found from pass 0's votes on a thread of
        # their own while passes 1 and 2 run.
        self._lines: Future[tuple[B, F32, F32]] | None = None
        # The E-step's parts on the worker thread not yet added: (their future, this
        # thread's own and counting seconds of that group, and its share).
        self._counting: list[tuple[Future[tuple[F64, F64, float]], float, float, float]] = []
        self._estep_share = WorkShare()

    def begin_pass(self, index: int) -> None:
        """Start pass ``index`` (module doc) over the same scans."""
        if index not in range(self.passes):
            raise ValueError(f"the forward method has passes 0 to 4, not {index}")
        self._counted()  # every E-step group's counts, before anything reads or resets them
        self._measuring = index == 2
        if index <= 1:
            super().begin_pass(index)
            if self._lines_on and index == 1:  # the votes are complete
                votes, res = self.votes, self.grid.resolution
                half_length = self.config.wall_line_half_length_m  # (the thread holds no mapper)
                self._lines = _on_own_thread(lambda: _near_lines(votes, res, half_length))
        elif index == 2:
            self._find_surfaces()
            self.surfaces = AttributionMapper.occupied(self)
            self.surface_index, self.surface_cols = cell_lists(self.surfaces)
            self.stats[:] = 0.0
            self.reaches[:] = 0.0
            self.pass_index = 2
            self._group_index = 0
        else:
            if index == 3:
                self.p_d = fitted_detection(self.stats)
                floor = fit_detection(self.stats)[3]  # the coincidences' rate
                self.v_unknown = unknown_rate(self.p_d, floor)
                self.p_reach = reach_detection(self.reaches)
                self.table = evidence_table(pass_evidence(self.p_reach))
                self.cos_table = cos_table(self.table)
            super().begin_pass(index - 1)
            if self._lines_on and index == 3:
                self._own = (self.nx, self.ny, self.consistency)
                self._use_lines()  # new arrays
                self.later_surfaces = self._own  # pass 3 flags the readings pass 4's stop
            elif self._own is not None and index == 4:
                self.nx, self.ny, self.consistency = self._own
                self._own = self.later_surfaces = None

    def _use_lines(self) -> None:
        """Pass 3 judges passes within :data:`NEAR_LINE_M` of an estimated wall line
        (:mod:`pipeline.mapper.wall_lines`) against the line: its normal, consistency 1;
        elsewhere the cells keep their own arcs' normals and consistency."""
        near, lnx, lny = self._lines.result() if self._lines else _near_lines(
            self.votes, self.grid.resolution, self.config.wall_line_half_length_m)
        self._lines = None
        self.nx = np.where(near, lnx, self.nx)
        self.ny = np.where(near, lny, self.ny)
        self.consistency = np.where(near, np.float32(1.0), self.consistency)

    def _integrate_group(self, group: ScanGroup) -> None:
        if self._lines_on and self.pass_index == 0:
            cat, g = group.cat, self.grid
            r: F64 = np.where(group.codes == rq.OK, cat.range_m, 0.0)
            vote_tangents(cat.origin_x, cat.origin_y, cat.alpha, 0.5 * cat.fov, r,
                          g.origin_x, g.origin_y, g.resolution, self.votes)
        if not self._measuring:
            super()._integrate_group(group)
            return
        started = time.thread_time()
        g, cfg = self.grid, self.config
        cat = group.cat
        d: F64 = np.where(group.codes == rq.OK, cat.range_m, 0.0)
        band = np.maximum(cfg.attr_band_sigmas * distance_sigma(d, cfg), 0.5 * g.resolution)
        silent = (group.codes == rq.MAX_RANGE) & np.isfinite(cat.max_range)
        free_r: F64 = np.where(silent, cat.max_range - cfg.eps_max, group.free_radius)
        outer: F64 = np.where(silent, free_r, np.where(d > 0.0, d + band, 0.0))
        rows, cones, up_down = cone_table(cat, outer)
        r_inner = np.where(d > 0.0, np.maximum(d - band, 0.0), np.inf)[rows]
        half = np.minimum(0.5 * cat.fov[rows], 0.5 * math.pi - 1e-9)
        r_free, alpha = free_r[rows], cat.alpha[rows]
        # The kernel's arguments taken now: the worker thread holds arrays, not the mapper.
        surfaces = (self.surface_index, self.surface_cols, self.nx, self.ny, self.consistency)
        bins = self.stats.shape[1] - 1

        def count(lo: int, hi: int) -> tuple[F64, F64, float]:
            # Each part of the readings counts into its own tables (integer counts: their
            # sums do not depend on the split); returns them and its thread CPU seconds.
            t = time.thread_time()
            stats, reaches = np.zeros((2, bins + 1)), np.zeros((2, bins))
            detection_counts(
                cones[lo:hi], up_down[lo:hi], r_inner[lo:hi], r_free[lo:hi], alpha[lo:hi],
                half[lo:hi], g.origin_x, g.origin_y, g.resolution, *surfaces, stats, reaches,
            )
            return stats, reaches, time.thread_time() - t

        n = len(rows)
        if not self._bands.parallel:
            self._add_counts(count(0, n))
            return
        # The worker counts the last readings of the group beside this thread's next
        # group (WorkShare balances the two); nothing waits for it before pass 3.
        share = self._estep_share.share
        cut = round(share * n)
        theirs = self._bands.later(lambda: count(cut, n))
        own = time.thread_time() - started
        mine = count(0, cut)
        self._add_counts(mine)
        self._counting.append((theirs, own, mine[2], share))
        self._counted(keep=COUNT_BACKLOG)

    def _add_counts(self, part: tuple[F64, F64, float]) -> None:
        self.stats += part[0]
        self.reaches += part[1]

    def _counted(self, keep: int = 0) -> None:
        """Add the E-step counts the worker has done (all but ``keep`` groups: waits for
        them) and balance the next groups by their times."""
        while self._counting and (len(self._counting) > keep or self._counting[0][0].done()):
            theirs, own, mine, share = self._counting.pop(0)
            part = theirs.result()
            self._add_counts(part)
            self._estep_share.update(own, mine, part[2], share)
