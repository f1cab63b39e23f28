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

* ``oracle=reach|full`` (reads the truth: an upper bound, not a method): the true walls
  within 0.10 m of a tangent vote (what a perfect line detector could find from these
  echoes) take the true wall's normal with consistency 1 in pass 3; elsewhere the method's
  own (``reach``) or, as :mod:`benchmarks.research.line_oracle`, consistency 0 and ``v̄ = 1``
  (``full``). :data:`TRUTH` is the row's truth map (set by the caller).

Variants combine with commas (``stops3=on,stops4=on``).
"""

from __future__ import annotations

import math

import numpy as np

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


def vote_reach_oracle(m: object, full: bool) -> None:
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
    dist, (ir, ic) = distance_transform_edt(~walls, return_indices=True)
    near = dist <= NEAR_LINE_M / g.resolution
    m.nx = np.where(near, nx[ir, ic], m.nx).astype(np.float32)  # type: ignore[attr-defined]
    m.ny = np.where(near, ny[ir, ic], m.ny).astype(np.float32)  # type: ignore[attr-defined]
    rest = 0.0 if full else m.consistency  # type: ignore[attr-defined]
    m.consistency = np.where(near, 1.0, rest).astype(np.float32)  # type: ignore[attr-defined]
    if full:
        m.v_unknown = 1.0  # type: ignore[attr-defined]


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
        if "link" in opts:
            on, nx, ny = link_segments(on, nx, ny, float(opts["link"]) / g.resolution)
        if "votes" in opts:
            von, vnx, vny = vote_segments(self.votes, float(opts["votes"]) / g.resolution)
            add = von & ~on
            on, nx, ny = on | von, np.where(add, vnx, nx), np.where(add, vny, ny)
        near, lnx, lny = near_lines(on, nx, ny, NEAR_LINE_M / g.resolution)
        self.nx = np.where(near, lnx, self.nx)
        self.ny = np.where(near, lny, self.ny)
        self.consistency = np.where(near, np.float32(1.0), self.consistency)
        self._q57_masks = (on, near)  # type: ignore[attr-defined]
        self._q57_arrays = (self.nx, self.ny, self.consistency)  # type: ignore[attr-defined]
        if "stops3" in opts:
            self.occ_index, self.occ_cols = stoppers(self, opts["stops3"])
        if "oracle" in opts:
            vote_reach_oracle(self, opts["oracle"] == "full")

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

    ForwardMapper._use_lines = own_then_lines  # type: ignore[method-assign]
    ForwardMapper.begin_pass = begin_pass  # type: ignore[method-assign]
