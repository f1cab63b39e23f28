"""The free-space scan of one scan (ALGORITHM.md §3).

For each reading with an echo at range ``d``: the cells whose centre lies in the cone
``|wrap(bearing − α)| ≤ β/2`` at distance ``< d − κ_free·σ_d(d)`` from the sonar origin,
so a cone stops short of its own obstacle. Readings at maximum range (``d ≥ r_max − ε_max``
or +inf) clear nothing unless ``clear_on_max_range``; then they clear up to ``r_max`` (when
the reading has a finite, positive ``r_max``). Other skipped readings (NaN, −inf, negative,
below r_min) clear nothing. The scan's free-space scan is the union over its readings: a
cell counts once per scan.

Cones are rasterised as row spans (:mod:`pipeline.mapper.grid_raster`), vectorised across
the readings of a scan, and clipped to the grid. The union is held as a boolean *window*
(the bounding box of all spans), built from a per-row difference array (+1 at each span's
first column, −1 after its last, running sum > 0), so the work is O(spans + window) and no
span is expanded to cells. Membership tests for the correction are a single fancy index
into the window padded by a one-cell border; the flat cell list is derived on demand.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from pipeline.config import MapperConfig
from pipeline.mapper.grid_raster import Spans, cone_edges, sector_spans
from pipeline.mapper.reading_features import distance_sigma
from pipeline.mapper.types import F64, I64, B, GridSpec, Scan
from pipeline.stages import reading_quality as rq


class FreeSpaceScan:
    """Union of one scan's free cones: ``mask[r − row0, c − col0]`` is True for free cells.

    ``cells`` (flat grid indices, ascending) and ``prefix`` (per-row running count of free
    cells, for span tests) are derived from the mask on first use.
    """

    __slots__ = ("_cells", "_padded", "_prefix", "_width", "col0", "count", "mask", "row0")

    def __init__(
        self, row0: int, col0: int, mask: B, grid_width: int = 0, count: int | None = None
    ) -> None:
        self.row0 = row0
        self.col0 = col0
        self.mask = mask
        self.count = int(np.count_nonzero(mask)) if count is None else count
        self._width = grid_width
        self._cells: I64 | None = None
        self._prefix: npt.NDArray[np.int32] | None = None
        self._padded: B | None = None

    @property
    def cells(self) -> I64:
        """Flat grid indices (row·width + col) of the free cells, ascending."""
        if self._cells is None:
            w = self.mask.shape[1]
            idx = np.flatnonzero(self.mask)
            self._cells = (idx // w + self.row0) * self._width + (idx % w + self.col0)
        return self._cells

    @property
    def padded_outside(self) -> B:
        """Cells *not* free, over the window grown by one cell each side, ``(h + 2, w + 2)``."""
        if self._padded is None:
            h, w = self.mask.shape
            pad = np.ones((h + 2, w + 2), dtype=np.bool_)
            np.logical_not(self.mask, out=pad[1 : h + 1, 1 : w + 1])
            self._padded = pad
        return self._padded

    @property
    def prefix(self) -> npt.NDArray[np.int32]:
        """``prefix[r, c]`` = free cells in window row r before window column c, (h, w + 1)."""
        if self._prefix is None:
            h, w = self.mask.shape
            pre = np.zeros((h, w + 1), dtype=np.int32)
            np.cumsum(self.mask, axis=1, out=pre[:, 1:])
            self._prefix = pre
        return self._prefix

    def contains(self, row: I64, col: I64) -> B:
        """Whether each cell (row, col) is free; cells outside the window/grid are not."""
        h, w = self.mask.shape
        if h == 0 or w == 0:
            return np.zeros(row.shape, dtype=np.bool_)
        lr = row - self.row0
        lc = col - self.col0
        inside = (lr >= 0) & (lr < h) & (lc >= 0) & (lc < w)
        flat = np.where(inside, lr * w + lc, 0)
        out: B = self.mask.reshape(-1)[flat] & inside
        return out


def empty_free_space() -> FreeSpaceScan:
    """A free-space scan with no cells."""
    return FreeSpaceScan(0, 0, np.zeros((0, 0), dtype=np.bool_))


def free_radius(
    scan: Scan, codes: npt.NDArray[np.int8], config: MapperConfig, margin: F64 | None = None
) -> F64:
    """Free range of each reading's cone, m; 0 where the reading clears nothing.

    ``margin`` is subtracted from the range of echo readings; by default it is
    ``κ_free·σ_d(d)`` (§3).
    """
    d = scan.range_m
    ok = codes == rq.OK
    radius = np.zeros(d.shape, dtype=np.float64)
    if margin is None:
        margin = config.kappa_free * distance_sigma(np.where(ok, d, 0.0), config)
    radius[ok] = d[ok] - margin[ok]
    if config.clear_on_max_range:
        r_max = scan.max_range
        with np.errstate(invalid="ignore"):
            far = ((codes == rq.MAX_RANGE) | (codes == rq.POS_INF)) & np.isfinite(r_max) & (r_max > 0)
        radius[far] = r_max[far]
    return np.maximum(radius, 0.0)


def cone_spans(scan: Scan, radius: F64, grid: GridSpec) -> tuple[I64, Spans]:
    """Spans of the cones with positive ``radius`` (m); ``owner`` indexes the returned rows."""
    rows = np.flatnonzero(radius > 0).astype(np.int64)
    spans = sector_spans(
        scan.origin_x[rows],
        scan.origin_y[rows],
        scan.alpha[rows],
        0.5 * scan.fov[rows],
        radius[rows],
        grid,
    )
    return rows, spans


def cone_table(scan: Scan, radius: F64) -> tuple[I64, F64, B]:
    """The cones with positive ``radius`` (m) as the compiled rasteriser takes them.

    Returns the scan rows, ``(k, 7)`` columns ``ox, oy, radius, sin e1, cos e1, sin e2,
    cos e2`` and ``(k, 2)`` whether each wedge holds +90° / −90° — the values
    :func:`cone_spans` computes, from the same numpy calls.
    """
    rows = np.flatnonzero(radius > 0).astype(np.int64)
    s1, c1, s2, c2, up, down = cone_edges(scan.alpha[rows], 0.5 * scan.fov[rows])
    cones = np.stack([scan.origin_x[rows], scan.origin_y[rows], radius[rows], s1, c1, s2, c2],
                     axis=1)
    return rows, cones, np.stack([up, down], axis=1)


def union_of_spans(spans: Spans, grid: GridSpec) -> FreeSpaceScan:
    """The union of span cells as a windowed mask.

    Each span adds +1 at its first column and −1 after its last in a per-row difference
    array; a running sum along rows counts covering spans, so the work is O(spans + window)
    with no per-cell expansion.
    """
    if len(spans) == 0:
        return empty_free_space()
    r0 = int(spans.row.min())
    c0 = int(spans.c0.min())
    h = int(spans.row.max()) - r0 + 1
    w = int(spans.c1.max()) - c0 + 1
    base = (spans.row - r0) * (w + 1) - c0
    size = h * (w + 1)
    diff = np.bincount(base + spans.c0, minlength=size)
    diff -= np.bincount(base + spans.c1 + 1, minlength=size)
    cover = np.cumsum(diff.reshape(h, w + 1)[:, :w], axis=1)
    return FreeSpaceScan(r0, c0, cover > 0, grid.width)


def free_space_scan(
    scan: Scan, codes: npt.NDArray[np.int8], config: MapperConfig, grid: GridSpec
) -> FreeSpaceScan:
    """The free-space scan of one scan (§3), clipped to the grid."""
    _, spans = cone_spans(scan, free_radius(scan, codes, config), grid)
    return union_of_spans(spans, grid)


# Cells of windows (int64 difference array) built at once by ``unions_of_spans``: bounds
# the temporary memory of a batch (~8 MB per array) while keeping the numpy call count per scan low.
_BATCH_CELLS = 1_000_000


def free_space_scans(
    scan: Scan, bounds: I64, codes: npt.NDArray[np.int8], config: MapperConfig, grid: GridSpec
) -> list[FreeSpaceScan]:
    """The free-space scans of many scans at once (identical to :func:`free_space_scan` each).

    ``scan`` holds the scans' readings concatenated; scan ``k`` is rows
    ``bounds[k]:bounds[k + 1]``. The cones are rasterised in one vectorised pass (the
    per-scan cost is numpy call overhead, not arithmetic).
    """
    rows, spans = cone_spans(scan, free_radius(scan, codes, config), grid)
    # Spans come grouped by reading, readings by scan: each scan's spans are one run.
    scan_of_span = np.searchsorted(bounds, rows[spans.owner], side="right") - 1
    n_scans = bounds.shape[0] - 1
    cuts = np.searchsorted(scan_of_span, np.arange(n_scans + 1))
    return unions_of_spans(spans, cuts, grid)


def unions_of_spans(spans: Spans, cuts: I64, grid: GridSpec) -> list[FreeSpaceScan]:
    """:func:`union_of_spans` of each group of spans ``cuts[k]:cuts[k + 1]``.

    The groups' windows are laid out one after the other in one flat difference array;
    every window row's +1/−1 pairs cancel within the row (a span ends at most in the
    row's spare last column), so one running sum over the whole array restarts at zero at
    every row and every window.
    """
    n = cuts.shape[0] - 1
    out: list[FreeSpaceScan] = [empty_free_space()] * n
    sizes = np.diff(cuts)
    have = np.flatnonzero(sizes > 0)
    if have.shape[0] == 0:
        return out
    starts = cuts[have]
    r0 = np.minimum.reduceat(spans.row, starts)
    r1 = np.maximum.reduceat(spans.row, starts)
    c0 = np.minimum.reduceat(spans.c0, starts)
    c1 = np.maximum.reduceat(spans.c1, starts)
    h = r1 - r0 + 1
    w1 = c1 - c0 + 2  # window width + the spare column
    cells = h * w1
    # Batches of windows, each at most _BATCH_CELLS (a single bigger window is its own).
    first = 0
    m = have.shape[0]
    ends = np.cumsum(cells)
    while first < m:
        base_cells = int(ends[first - 1]) if first else 0
        last = int(np.searchsorted(ends, base_cells + _BATCH_CELLS, side="right"))
        last = max(last, first + 1)
        g = slice(first, last)
        lo, hi = int(starts[first]), int(cuts[have[last - 1] + 1])
        grp = np.repeat(np.arange(last - first), sizes[have[g]])
        offset = ends[g] - cells[g] - base_cells
        base = offset[grp] + (spans.row[lo:hi] - r0[g][grp]) * w1[g][grp] - c0[g][grp]
        total = int(ends[last - 1]) - base_cells
        diff = np.bincount(base + spans.c0[lo:hi], minlength=total)
        diff -= np.bincount(base + spans.c1[lo:hi] + 1, minlength=total)
        cover = np.cumsum(diff) > 0
        counts = np.add.reduceat(cover, offset, dtype=np.int64).tolist()
        for j, k in enumerate(have[g].tolist()):
            a = int(offset[j])
            hj, wj = int(h[first + j]), int(w1[first + j])
            mask = cover[a : a + hj * wj].reshape(hj, wj)[:, : wj - 1]
            out[k] = FreeSpaceScan(
                int(r0[first + j]), int(c0[first + j]), mask, grid.width, counts[j]
            )
        first = last
    return out
