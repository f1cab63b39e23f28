"""Variants of the default's wall lines measured for issue 57 (docs/research/forward_walls.md §6).

None is in the pipeline: each is installed on :class:`pipeline.mapper.forward.ForwardMapper`
by :func:`install` (as :mod:`benchmarks.research.line_oracle` does) and scored by
:mod:`benchmarks.research.wall_lines_rows` (``--variant NAME``).

* ``stops3=near|on``: in pass 3 (the surface-aware count) the wall lines' cells stop rays
  too: the silent-surface candidates are the first map's cells with ``q > ½`` (``q`` as
  the lines set it) and the lines' 0.10 m band (``near``) or the line cells (``on``).
* ``stops4=near|on``: the same stops, with the lines' normals, in pass 4 (the final
  attribution: an echo cannot come from behind a line that stopped its ray).
* ``link=G``: line cells of one normal bin joined into segments across gaps up to ``G`` m
  (:func:`link_segments`).
* ``votes=G``: segments between any two vote cells of one bin up to ``G`` m apart on the
  bin's line (:func:`vote_segments`), added to the lines.

* ``votecells=K``: every vote cell whose bin has ``K`` distinct vote cells in the line
  test's box (:func:`vote_cells`), added to the lines.
* ``llr=1``: the line cells (after the other options) kept only where the bin's votes in
  the box outweigh the head-on passes through the voted cells (:func:`supported`; the
  passes counted in pass 0 by :func:`vote_passes`).
* ``offfull=1``: cells away from the lines (after the other options) get consistency 0
  and ``v̄ = 1`` in pass 3 (a pass there counts in full: §3's substitution).
* ``oracle=reach|reachbin|full`` (reads the truth: an upper bound, not a method): the true walls
  within 0.10 m of a tangent vote (what a perfect line detector could find from these
  echoes) take the true wall's normal with consistency 1 in pass 3; elsewhere the method's
  own (``reach``) or, as :mod:`benchmarks.research.line_oracle`, consistency 0 and ``v̄ = 1``
  (``full``); ``reachbin``: ``reach`` with the normals rounded to the line bins' centres.
  :data:`TRUTH` is the row's truth map (set by the caller).

Variants combine with commas (``stops3=on,stops4=on``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from pipeline.mapper.kernels.specular import cell_lists
from pipeline.mapper.types import F32, B
from pipeline.mapper.wall_lines import LINE_BINS, NEAR_LINE_M, Votes, near_lines, wall_lines

TRUTH: list[object] = []  # the current row's truth map (a Path), for ``oracle``
TILT = math.tan(0.5 * math.pi / LINE_BINS)  # half a bin: the direction two cells may join in


def _segments(cells: B, b: int, gap_cells: float, slack: float, min_dt: float) -> B:
    """The cells on the segments joining pairs of bin ``b``'s ``cells``: ``min_dt`` to
    ``gap_cells`` cells apart along the bin's line, across it at most half a bin's tilt over
    that distance plus ``slack`` cells (the pairs' ends included; unpaired cells not)."""
    out: B = np.zeros_like(cells)
    rows, cols = np.nonzero(cells)
    if rows.size < 2:
        return out
    p = (b + 0.5) * math.pi / LINE_BINS
    c, s = math.cos(p), math.sin(p)
    r, q = rows.astype(np.float64), cols.astype(np.float64)
    tn, tt = q * c + r * s, r * c - q * s
    order = np.argsort(tt, kind="stable")
    tn, tt, r, q = tn[order], tt[order], r[order], q[order]
    for i in range(len(tt)):
        for j in range(i + 1, len(tt)):
            dt = tt[j] - tt[i]
            if dt > gap_cells:
                break
            if dt < min_dt or abs(tn[j] - tn[i]) > TILT * dt + slack:
                continue
            m = math.ceil(2.0 * math.hypot(r[j] - r[i], q[j] - q[i])) + 1
            f = np.linspace(0.0, 1.0, m)
            out[np.floor(r[i] + f * (r[j] - r[i]) + 0.5).astype(np.int64),
                np.floor(q[i] + f * (q[j] - q[i]) + 0.5).astype(np.int64)] = True
    return out


def _bins_of(nx: F32, ny: F32) -> np.ndarray:
    psi = np.mod(np.arctan2(ny, nx), math.pi)
    out: np.ndarray = np.round(psi / (math.pi / LINE_BINS) - 0.5).astype(np.int64) % LINE_BINS
    return out


def _with_bin(out: B, onx: F32, ony: F32, add: B, b: int) -> None:
    p = (b + 0.5) * math.pi / LINE_BINS
    out |= add
    onx[add], ony[add] = np.float32(math.cos(p)), np.float32(math.sin(p))


def link_segments(on: B, nx: F32, ny: F32, gap_cells: float) -> tuple[B, F32, F32]:
    """Line cells of one normal bin joined across gaps up to ``gap_cells`` (a wall runs on
    where the sonar did not hear it); the cells added take the bin's normal."""
    out, onx, ony = on.copy(), nx.copy(), ny.copy()
    bins = _bins_of(nx, ny)
    for b in range(LINE_BINS):
        _with_bin(out, onx, ony, _segments(on & (bins == b), b, gap_cells, 0.0, 1.0) & ~out, b)
    return out, onx, ony


def vote_segments(votes: Votes, gap_cells: float, slack: float = 0.5) -> tuple[B, F32, F32]:
    """Segments between two vote cells of one bin, 2 to ``gap_cells`` cells apart along the
    bin's line (two places agree on one tangent line); the bin's normal (a later bin's
    wins where two overlap)."""
    bins, h, w = votes.shape
    out: B = np.zeros((h, w), dtype=bool)
    onx: F32 = np.zeros((h, w), dtype=np.float32)
    ony: F32 = np.zeros((h, w), dtype=np.float32)
    for b in range(bins):
        _with_bin(out, onx, ony, _segments(votes[b] > 0, b, gap_cells, slack, 2.0), b)
    return out, onx, ony


def vote_reach_oracle(m: object, full: bool, binned: bool = False) -> None:
    """``oracle=`` (module doc): the truth's walls near a vote, with the truth's normals."""
    from scipy.ndimage import distance_transform_edt

    from formats.writers.nav2_map import load_nav2_map
    from pipeline.tools.evaluate import OCCUPIED, resample_classes
    from pipeline.tools.sonar.grid_scene import wall_normals

    g = m.grid  # type: ignore[attr-defined]
    truth = load_nav2_map(TRUTH[0])  # type: ignore[arg-type]
    walls = resample_classes(truth.classes, truth.grid, g)[0] == OCCUPIED
    voted = m.votes.sum(axis=0) > 0  # type: ignore[attr-defined]
    walls &= distance_transform_edt(~voted) <= NEAR_LINE_M / g.resolution
    if not walls.any():
        return
    nx, ny, _ = wall_normals(walls, g.resolution)
    if binned:  # the normal of the nearest line bin's centre, as a line detector gives
        b = _bins_of(nx.astype(np.float32), ny.astype(np.float32))
        p = (b + 0.5) * math.pi / LINE_BINS
        nx, ny = np.cos(p), np.sin(p)
    dist, (ir, ic) = distance_transform_edt(~walls, return_indices=True)
    near = dist <= NEAR_LINE_M / g.resolution
    m.nx = np.where(near, nx[ir, ic], m.nx).astype(np.float32)  # type: ignore[attr-defined]
    m.ny = np.where(near, ny[ir, ic], m.ny).astype(np.float32)  # type: ignore[attr-defined]
    rest = 0.0 if full else m.consistency  # type: ignore[attr-defined]
    m.consistency = np.where(near, 1.0, rest).astype(np.float32)  # type: ignore[attr-defined]
    if full:
        m.v_unknown = 1.0  # type: ignore[attr-defined]


def vote_cells(votes: Votes, least: int, half_cells: float) -> tuple[B, F32, F32]:
    """Every vote cell whose bin has votes in at least ``least`` distinct cells of the
    box of half side ``half_cells`` around it, with the normal of the bin with the most."""
    from pipeline.mapper.specular import box_sum

    n = max(1, round(half_cells))
    bins, h, w = votes.shape
    best = np.zeros((h, w))
    onx: F32 = np.zeros((h, w), dtype=np.float32)
    ony: F32 = np.zeros((h, w), dtype=np.float32)
    for b in range(bins):
        v = votes[b] > 0
        if not v.any():
            continue
        m = box_sum(v.astype(np.float32), n)
        ok = v & (m >= least) & (m > best)
        p = (b + 0.5) * math.pi / bins
        best = np.where(ok, m, best)
        onx[ok], ony[ok] = np.float32(math.cos(p)), np.float32(math.sin(p))
    return best > 0, onx, ony


@njit(cache=True)
def vote_passes(ox: np.ndarray, oy: np.ndarray, alpha: np.ndarray, half: np.ndarray,
                reach: np.ndarray, gx: float, gy: float, res: float,
                passes: np.ndarray) -> None:
    """Per reading, along each line bin's centre direction ψ inside its cone (as
    :func:`pipeline.mapper.kernels.lines.vote_tangents`), every cell the ray ψ crosses short
    of ``reach`` (the echo's arc, or ``r_max`` with no echo) gets one head-on pass in
    ``passes[bin]``: a wall of normal ψ there would have faced the sonar."""
    bins, height, width = passes.shape
    step = math.pi / bins
    for i in range(len(reach)):
        if not reach[i] > 0.0:
            continue
        j0 = math.ceil((alpha[i] - half[i]) / step - 0.5 - 1e-9)
        j1 = math.floor((alpha[i] + half[i]) / step - 0.5 + 1e-9)
        n = int(reach[i] / (0.5 * res))
        for j in range(j0, j1 + 1):
            psi = (j + 0.5) * step
            c, s = math.cos(psi), math.sin(psi)
            b = j % bins
            last_r, last_c = -1, -1
            for k in range(n):
                rho = (k + 0.5) * 0.5 * res
                col = math.floor((ox[i] + rho * c - gx) / res)
                row = math.floor((oy[i] + rho * s - gy) / res)
                if row == last_r and col == last_c:
                    continue
                last_r, last_c = row, col
                if 0 <= row < height and 0 <= col < width and passes[b, row, col] < 65535:
                    passes[b, row, col] += 1


def supported(on: B, nx: F32, ny: F32, votes: Votes, passes: np.ndarray, half_cells: float,
              p0: float, floor: float) -> B:
    """The line cells whose bin's votes in the box outweigh the head-on passes through the
    voted cells: ``S·ln(p0/f) + C·ln((1 − p0)/(1 − f)) > 0`` (``S`` votes, ``C`` passes;
    ``p0`` the measured head-on detection, ``f`` the coincidences' rate)."""
    from pipeline.mapper.specular import box_sum

    n = max(1, round(half_cells))
    bins = _bins_of(nx, ny)
    f = min(max(floor, 1e-3), 0.5 * p0)
    a, b_ = math.log(p0 / f), math.log((1.0 - p0) / (1.0 - f))
    out: B = np.zeros_like(on)
    for b in range(LINE_BINS):
        mine = on & (bins == b)
        if not mine.any():
            continue
        v = votes[b].astype(np.float32)
        c = np.where(votes[b] > 0, passes[b], 0).astype(np.float32)
        llr = box_sum(v, n) * a + box_sum(c, n) * b_
        out |= mine & (llr > 0.0)
    return out


def install(variant: str) -> None:
    """Patch ForwardMapper with the comma-separated ``variant`` (module doc)."""
    from pipeline.mapper.forward import ForwardMapper

    opts = dict(v.split("=", 1) for v in variant.split(",") if v)
    begin = ForwardMapper.begin_pass

    def stoppers(self: ForwardMapper, kind: str) -> tuple[np.ndarray, np.ndarray]:
        on, near = self._q57_masks  # type: ignore[attr-defined]
        cells = self.surfaces & (self._q57_arrays[2] > 0.5)  # type: ignore[attr-defined]
        return cell_lists(cells | (near if kind == "near" else on))

    def use_lines(self: ForwardMapper) -> None:
        g = self.grid
        on, nx, ny = wall_lines(self.votes, g.resolution, self.config.wall_line_half_length_m)
        if "votecells" in opts:
            von, vnx, vny = vote_cells(self.votes, int(opts["votecells"]),
                                       self.config.wall_line_half_length_m / g.resolution)
            add = von & ~on
            on, nx, ny = on | von, np.where(add, vnx, nx), np.where(add, vny, ny)
        if "link" in opts:
            on, nx, ny = link_segments(on, nx, ny, float(opts["link"]) / g.resolution)
        if "votes" in opts:
            von, vnx, vny = vote_segments(self.votes, float(opts["votes"]) / g.resolution)
            add = von & ~on
            on, nx, ny = on | von, np.where(add, vnx, nx), np.where(add, vny, ny)
        if "llr" in opts:
            from pipeline.mapper.forward import fit_detection

            keep = supported(on, nx, ny, self.votes, self._q57_passes,  # type: ignore[attr-defined]
                             self.config.wall_line_half_length_m / g.resolution,
                             float(self.p_reach[0]), fit_detection(self.stats)[3])
            on = keep
        near, lnx, lny = near_lines(on, nx, ny, NEAR_LINE_M / g.resolution)
        self.nx = np.where(near, lnx, self.nx)
        self.ny = np.where(near, lny, self.ny)
        self.consistency = np.where(near, np.float32(1.0), self.consistency)
        if "offfull" in opts:  # §3's substitution: away from the lines passes count in full
            self.consistency = np.where(near, self.consistency, np.float32(0.0))
            self.v_unknown = 1.0
        self._q57_masks = (on, near)  # type: ignore[attr-defined]
        self._q57_arrays = (self.nx, self.ny, self.consistency)  # type: ignore[attr-defined]
        if "stops3" in opts:
            self.occ_index, self.occ_cols = stoppers(self, opts["stops3"])
        if "oracle" in opts:
            vote_reach_oracle(self, opts["oracle"] == "full", opts["oracle"] == "reachbin")

    def begin_pass(self: ForwardMapper, index: int) -> None:
        begin(self, index)
        if index == 4:
            if "stops4" in opts:
                # the lines' normals (new arrays: pass 3's shadows are not reused)
                nx, ny, q = self._q57_arrays  # type: ignore[attr-defined]
                self.nx, self.ny, self.consistency = nx.copy(), ny.copy(), q.copy()
                self.occ_index, self.occ_cols = stoppers(self, opts["stops4"])
            elif "stops3" in opts:
                self.occ_index, self.occ_cols = self._own_occ  # type: ignore[attr-defined]

    def own_then_lines(self: ForwardMapper) -> None:
        self._own_occ = (self.occ_index, self.occ_cols)  # type: ignore[attr-defined]
        use_lines(self)

    integrate = ForwardMapper._integrate_group

    def integrate_group(self: ForwardMapper, group: object) -> None:
        if "llr" in opts and self.pass_index == 0:
            from pipeline.mapper.reading_features import distance_sigma
            from pipeline.stages import reading_quality as rq

            cat, g, cfg = group.cat, self.grid, self.config  # type: ignore[attr-defined]
            codes = group.codes  # type: ignore[attr-defined]
            d = np.where(codes == rq.OK, cat.range_m, 0.0)
            band = np.maximum(cfg.attr_band_sigmas * distance_sigma(d, cfg), 0.5 * g.resolution)
            silent = (codes == rq.MAX_RANGE) & np.isfinite(cat.max_range)
            reach = np.where(silent, cat.max_range - cfg.eps_max, np.maximum(d - band, 0.0))
            if not hasattr(self, "_q57_passes"):
                self._q57_passes = np.zeros_like(self.votes)  # type: ignore[attr-defined]
            vote_passes(cat.origin_x, cat.origin_y, cat.alpha, 0.5 * cat.fov, reach,
                        g.origin_x, g.origin_y, g.resolution,
                        self._q57_passes)  # type: ignore[attr-defined]
        integrate(self, group)  # type: ignore[arg-type]

    ForwardMapper._integrate_group = integrate_group  # type: ignore[method-assign]
    ForwardMapper._use_lines = own_then_lines  # type: ignore[method-assign]
    ForwardMapper.begin_pass = begin_pass  # type: ignore[method-assign]
