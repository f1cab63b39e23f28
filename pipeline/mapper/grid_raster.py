"""Rasterising sonar cones and covariance ellipses onto the grid, as row spans.

Every shape the mapper draws is convex along a grid row, so it is described by *spans*:
``(owner, row, c0, c1)`` = columns ``c0..c1`` (inclusive) of ``row`` belong to shape
``owner``. Spans are computed analytically per (shape, row) pair — a handful of numpy
operations over a few hundred pairs per scan — and expanded to cells only where cells are
needed. This avoids both per-cell Python loops and testing every cell of each shape's
bounding window (a 30° cone fills about a quarter of its box).

A cell (row r, col c) is *inside* a shape when its centre
``(origin_x + (c + ½)·res, origin_y + (r + ½)·res)`` is (GridSpec convention). Shapes are
clipped to the grid: parts outside produce no spans.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from formats.angles import wrap_angle
from pipeline.mapper.types import F64, I64, B, GridSpec

# Beams of half-width ≥ 90° would need the union, not the intersection, of two half-planes;
# sonar beams are far narrower, so wider values are clamped just below 90°.
_MAX_HALF_BEAM = 0.5 * np.pi - 1e-9


@dataclass(frozen=True)
class Spans:
    """Row spans: columns ``c0[k]..c1[k]`` of ``row[k]`` belong to shape ``owner[k]``."""

    owner: I64
    row: I64
    c0: I64
    c1: I64

    def __len__(self) -> int:
        return int(self.owner.shape[0])

    def cell_count(self) -> int:
        return int((self.c1 - self.c0 + 1).sum())


def expand_ranges(start: I64, stop: I64) -> tuple[I64, I64]:
    """All integers ``start[k]..stop[k]`` (inclusive) for every k: ``(k, value)`` pairs.

    Empty ranges (stop < start) contribute nothing. Output is grouped by k, ascending.
    """
    n = np.maximum(stop - start + 1, 0)
    owner = np.repeat(np.arange(n.shape[0], dtype=np.int64), n)
    offsets = np.cumsum(n) - n
    value = np.arange(owner.shape[0], dtype=np.int64) - np.repeat(offsets - start, n)
    return owner, value


def span_cells(spans: Spans) -> tuple[I64, I64, I64]:
    """Expand spans to cells: ``(owner, row, col)`` per cell."""
    k, col = expand_ranges(spans.c0, spans.c1)
    return spans.owner[k], spans.row[k], col


def _rows_for(lo_y: F64, hi_y: F64, grid: GridSpec) -> tuple[I64, I64]:
    """Rows whose centre y lies in ``[lo_y, hi_y]`` (m), clipped to the grid."""
    res = grid.resolution
    r0 = np.ceil((lo_y - grid.origin_y) / res - 0.5)
    r1 = np.floor((hi_y - grid.origin_y) / res - 0.5)
    # Inputs are finite (the mapper skips readings with non-finite geometry).
    # np.minimum/np.maximum rather than np.clip: same values, a fraction of the call cost.
    r0 = np.minimum(np.maximum(r0, 0), grid.height)
    r1 = np.minimum(np.maximum(r1, -1), grid.height - 1)
    return r0.astype(np.int64), r1.astype(np.int64)


def _finish(owner: I64, row: I64, ox: F64, lo: F64, hi: F64, ok: np.ndarray, grid: GridSpec) -> Spans:
    """Turn per-row x intervals ``[ox+lo, ox+hi]`` (m) into clipped column spans."""
    res = grid.resolution
    with np.errstate(invalid="ignore"):
        c0 = np.ceil((ox + lo - grid.origin_x) / res - 0.5)
        c1 = np.floor((ox + hi - grid.origin_x) / res - 0.5)
        ok = ok & (c0 <= c1) & (c1 >= 0) & (c0 <= grid.width - 1)
    c0 = np.minimum(np.maximum(c0[ok], 0), grid.width - 1).astype(np.int64)
    c1 = np.minimum(np.maximum(c1[ok], 0), grid.width - 1).astype(np.int64)
    return Spans(owner[ok], row[ok], c0, c1)


def cone_edges(alpha: F64, half_beam: F64) -> tuple[F64, F64, F64, F64, B, B]:
    """Sines and cosines of the cone edges ``e1 = α − β/2``, ``e2 = α + β/2`` (half-width
    clamped to [0, 90°)), and whether the wedge holds the +90° / −90° direction."""
    hb = np.clip(half_beam, 0.0, _MAX_HALF_BEAM)
    e1 = alpha - hb
    e2 = alpha + hb
    up = np.abs(wrap_angle(0.5 * np.pi - alpha)) <= hb
    down = np.abs(wrap_angle(-0.5 * np.pi - alpha)) <= hb
    return np.sin(e1), np.cos(e1), np.sin(e2), np.cos(e2), up, down


def sector_spans(
    ox: F64, oy: F64, alpha: F64, half_beam: F64, radius: F64, grid: GridSpec
) -> Spans:
    """Cells of circular sectors: centre within ``radius`` (m, strict) of the origin ``(ox, oy)``
    and within ``half_beam`` (rad) of the axis angle ``alpha`` (rad), one sector per element.

    The wedge ``|wrap_angle(bearing − α)| ≤ β/2`` is the intersection of two half-planes bounded
    by the cone edges ``e1 = α − β/2`` and ``e2 = α + β/2``:
    ``cross(e1, p) ≥ 0`` and ``cross(p, e2) ≥ 0``; each clips the row's disk chord.
    """
    s1, c1, s2, c2, up, down = cone_edges(alpha, half_beam)
    # y extent of the sector: the origin, both edge tips, and ±radius if the wedge holds ±90°.
    ys = np.stack([np.zeros_like(radius), radius * s1, radius * s2])
    lo_y = ys.min(axis=0)
    hi_y = ys.max(axis=0)
    hi_y = np.where(up, radius, hi_y)
    lo_y = np.where(down, -radius, lo_y)
    r0, r1 = _rows_for(oy + lo_y, oy + hi_y, grid)
    k, row = expand_ranges(r0, r1)
    dy = grid.origin_y + (row + 0.5) * grid.resolution - oy[k]
    h2 = radius[k] ** 2 - dy * dy
    ok = h2 > 0
    h = np.sqrt(np.where(ok, h2, 0.0))
    lo, hi = -h, h
    s1k, c1k, s2k, c2k = s1[k], c1[k], s2[k], c2[k]
    with np.errstate(divide="ignore", invalid="ignore"):
        # edge e1: s1·dx ≤ c1·dy
        b1 = c1k * dy / s1k
        hi = np.where(s1k > 0, np.minimum(hi, b1), hi)
        lo = np.where(s1k < 0, np.maximum(lo, b1), lo)
        ok &= ~((s1k == 0) & (c1k * dy < 0))
        # edge e2: s2·dx ≥ c2·dy
        b2 = c2k * dy / s2k
        lo = np.where(s2k > 0, np.maximum(lo, b2), lo)
        hi = np.where(s2k < 0, np.minimum(hi, b2), hi)
        ok &= ~((s2k == 0) & (c2k * dy > 0))
    return _finish(k, row, ox[k], lo, hi, ok, grid)


def ellipse_spans(
    mx: F64, my: F64, cxx: F64, cxy: F64, cyy: F64, k_sigma: float, grid: GridSpec
) -> Spans:
    """Cells whose centre has Mahalanobis distance ≤ ``k_sigma`` from ``N(μ, P)``.

    Per row offset dy the ellipse chord is
    ``dx = (P_xy·dy ± sqrt(det P · (k²·P_yy − dy²))) / P_yy`` — solved in P, no inverse.
    """
    k2 = k_sigma * k_sigma
    cyy_safe = np.maximum(cyy, 1e-300)
    half_y = k_sigma * np.sqrt(cyy_safe)
    r0, r1 = _rows_for(my - half_y, my + half_y, grid)
    k, row = expand_ranges(r0, r1)
    dy = grid.origin_y + (row + 0.5) * grid.resolution - my[k]
    det = np.maximum(cxx[k] * cyy[k] - cxy[k] ** 2, 0.0)
    disc = det * (k2 * cyy[k] - dy * dy)
    ok = disc >= 0
    root = np.sqrt(np.where(ok, disc, 0.0))
    centre = cxy[k] * dy
    lo = (centre - root) / cyy_safe[k]
    hi = (centre + root) / cyy_safe[k]
    return _finish(k, row, mx[k], lo, hi, ok, grid)


def mean_cells(mx: F64, my: F64, grid: GridSpec) -> tuple[I64, I64, np.ndarray]:
    """Row and column of the cell containing each point, and whether it is inside the grid."""
    with np.errstate(invalid="ignore"):
        c = np.floor((mx - grid.origin_x) / grid.resolution)
        r = np.floor((my - grid.origin_y) / grid.resolution)
        inside = (c >= 0) & (c < grid.width) & (r >= 0) & (r < grid.height)
    r = np.where(inside, r, 0).astype(np.int64)
    c = np.where(inside, c, 0).astype(np.int64)
    return r, c, inside
