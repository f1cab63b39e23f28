"""Compiled per-reading loops over the cells of sonar cones and echo arcs (numba).

A reading's cone is the sector of half-angle ``hf`` around the beam axis ``alpha`` from the
sonar origin; a cell belongs to a shape when its *centre* does (the GridSpec convention of
:mod:`pipeline.mapper.grid_raster`): bearing test ``dot(p, axis) ≥ |p|·cos(hf)`` (half-angles
are clamped just below 90°), distance test strict at the outer radius of a free cone and
inclusive on both sides of an echo's arc band.

Each row of a shape is visited over the columns of its outer disk's chord clipped to the
shape's bounding box, so the work is proportional to the shape's area, not its box. Loops
run in reading order and add in that order, so results are deterministic.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

from pipeline.mapper.types import F32, F64

_MAX_HALF_BEAM = 0.5 * math.pi - 1e-9


@njit(cache=True, inline="always")
def _row_range(
    oy: float, a: float, hf: float, r: float, y0: float, res: float, n_rows: int
) -> tuple[int, int]:
    """Rows whose centres may lie in the sector (origin y ``oy``, radius ``r``)."""
    lo = min(0.0, r * math.sin(a - hf), r * math.sin(a + hf))
    hi = max(0.0, r * math.sin(a - hf), r * math.sin(a + hf))
    if abs((0.5 * math.pi - a + math.pi) % (2 * math.pi) - math.pi) <= hf:
        hi = r
    if abs((-0.5 * math.pi - a + math.pi) % (2 * math.pi) - math.pi) <= hf:
        lo = -r
    r0 = max(math.floor((oy + lo - y0) / res - 0.5), 0)
    r1 = min(math.ceil((oy + hi - y0) / res - 0.5), n_rows - 1)
    return r0, r1


@njit(cache=True, inline="always")
def _wedge(a: float, hf: float) -> tuple[float, float, float, float]:
    """sin and cos of the cone's two edges ``a − hf`` and ``a + hf``."""
    return math.sin(a - hf), math.cos(a - hf), math.sin(a + hf), math.cos(a + hf)


@njit(cache=True, inline="always")
def _col_range(
    ox: float, dy: float, lo: float, hi: float, s1: float, c1: float, s2: float, c2: float,
    x0: float, res: float, n_cols: int,
) -> tuple[int, int]:
    """Columns of one row (centre offset ``dy`` from the origin) whose centres may lie in
    ``[lo, hi]`` (x offsets from the origin) and inside the wedge between the edges
    (``s1·dx ≤ c1·dy`` and ``s2·dx ≥ c2·dy``), widened by one cell each side; the callers
    test every cell exactly, so the widening only guards the rounding of the bounds."""
    if s1 > 0.0:
        hi = min(hi, c1 * dy / s1)
    elif s1 < 0.0:
        lo = max(lo, c1 * dy / s1)
    elif c1 * dy < 0.0:
        return 0, -1
    if s2 > 0.0:
        lo = max(lo, c2 * dy / s2)
    elif s2 < 0.0:
        hi = min(hi, c2 * dy / s2)
    elif c2 * dy > 0.0:
        return 0, -1
    if lo > hi:
        return 0, -1
    c0 = max(math.floor((ox + lo - x0) / res - 0.5), 0)
    c1_ = min(math.ceil((ox + hi - x0) / res - 0.5), n_cols - 1)
    return c0, c1_


@njit(cache=True, inline="always")
def _inside(dx: float, dy: float, ca: float, sa: float, cos2: float) -> bool:
    """Whether the offset lies within the half-angle whose squared cosine is ``cos2``
    (half-angles below 90°): ``dot ≥ |p|·cos(hf)`` without a square root."""
    dot = dx * ca + dy * sa
    return dot >= 0.0 and dot * dot >= (dx * dx + dy * dy) * cos2


@njit(cache=True)
def count_free(
    ox: F64, oy: F64, alpha: F64, half_fov: F64, radius: F64,
    x0: float, y0: float, res: float, counts: F32,
) -> int:
    """Add 1 to ``counts`` at every cell of every reading's free cone (centre strictly
    within ``radius``); readings with ``radius ≤ 0`` clear nothing. Returns the cells added."""
    n_rows, n_cols = counts.shape
    total = 0
    for i in range(ox.shape[0]):
        r = radius[i]
        if not r > 0.0:
            continue
        hf = min(max(half_fov[i], 0.0), _MAX_HALF_BEAM)
        ca, sa = math.cos(alpha[i]), math.sin(alpha[i])
        cos2 = math.cos(hf) ** 2
        s1, c1, s2, c2 = _wedge(alpha[i], hf)
        r2 = r * r
        r0, r1 = _row_range(oy[i], alpha[i], hf, r, y0, res, n_rows)
        for row in range(r0, r1 + 1):
            dy = y0 + (row + 0.5) * res - oy[i]
            if dy * dy >= r2:
                continue
            h = math.sqrt(r2 - dy * dy)
            c0, c1_ = _col_range(ox[i], dy, -h, h, s1, c1, s2, c2, x0, res, n_cols)
            for col in range(c0, c1_ + 1):
                dx = x0 + (col + 0.5) * res - ox[i]
                if dx * dx + dy * dy >= r2 or not _inside(dx, dy, ca, sa, cos2):
                    continue
                counts[row, col] += 1.0
                total += 1
    return total


@njit(cache=True)
def _arc_cells(
    ox: float, oy: float, a: float, half_fov: float, d: float, band: float,
    x0: float, y0: float, res: float, n_rows: int, n_cols: int,
    rows: npt.NDArray[np.int64], cols: npt.NDArray[np.int64],
) -> int:
    """Write the cells of one echo's arc (in the cone, distance within ``d ± band``,
    inclusive) into ``rows``/``cols``, row by row; returns how many."""
    ro = d + band
    ri = max(d - band, 0.0)
    ro2, ri2 = ro * ro, ri * ri
    hf = min(max(half_fov, 0.0), _MAX_HALF_BEAM)
    ca, sa = math.cos(a), math.sin(a)
    cos2 = math.cos(hf) ** 2
    s1, c1, s2, c2 = _wedge(a, hf)
    r0, r1 = _row_range(oy, a, hf, ro, y0, res, n_rows)
    n = 0
    for row in range(r0, r1 + 1):
        dy = y0 + (row + 0.5) * res - oy
        if dy * dy > ro2:
            continue
        h = math.sqrt(ro2 - dy * dy)
        inner = math.sqrt(ri2 - dy * dy) if dy * dy < ri2 else 0.0
        # The annulus's row: [-h, -inner] and [inner, h] (one interval when inner = 0).
        for side in range(2):
            lo, hi = (-h, -inner) if side == 0 else (inner, h)
            if inner == 0.0 and side == 1:
                break
            if inner == 0.0:
                hi = h
            c0, c1_ = _col_range(ox, dy, lo, hi, s1, c1, s2, c2, x0, res, n_cols)
            for col in range(c0, c1_ + 1):
                dx = x0 + (col + 0.5) * res - ox
                d2 = dx * dx + dy * dy
                if d2 > ro2 or d2 < ri2 or not _inside(dx, dy, ca, sa, cos2):
                    continue
                rows[n] = row
                cols[n] = col
                n += 1
    return n


@njit(cache=True, inline="always")
def _arc_buffer(d: F64, band: F64, res: float) -> int:
    """Cells enough for the largest arc's bounding box."""
    reach = 0.0
    for i in range(d.shape[0]):
        if d[i] > 0.0:
            reach = max(reach, d[i] + band[i])
    k = 2 * math.ceil(reach / res) + 3
    return k * k


@njit(cache=True)
def count_arcs(
    ox: F64, oy: F64, alpha: F64, half_fov: F64, d: F64, band: F64,
    x0: float, y0: float, res: float, counts: F32,
) -> None:
    """Add 1 to ``counts`` at every cell of every echo's arc: in the cone, at a distance
    within ``d ± band`` of the origin (inclusive). Readings with ``d ≤ 0`` have no arc."""
    n_rows, n_cols = counts.shape
    size = _arc_buffer(d, band, res)
    rows = np.empty(size, dtype=np.int64)
    cols = np.empty(size, dtype=np.int64)
    for i in range(ox.shape[0]):
        if not d[i] > 0.0:
            continue
        n = _arc_cells(ox[i], oy[i], alpha[i], half_fov[i], d[i], band[i], x0, y0, res,
                       n_rows, n_cols, rows, cols)
        for k in range(n):
            counts[rows[k], cols[k]] += 1.0


@njit(cache=True)
def attribute_echoes(
    ox: F64, oy: F64, alpha: F64, half_fov: F64, d: F64, band: F64,
    x0: float, y0: float, res: float,
    free: F32, arcs: F32, candidate_ratio: float, dilution: float, hits: F32,
) -> int:
    """Spread each echo over the cells of its arc that may have produced it; returns the
    echoes with no such cell.

    A cell of the arc is a *candidate* unless the free-space evidence rules it out:
    ``free > candidate_ratio · arcs`` (it was seen free more often, by that factor, than
    echo arcs cover it). Each of the ``n`` candidates gets ``1 / n**dilution`` of the echo.
    """
    n_rows, n_cols = hits.shape
    size = _arc_buffer(d, band, res)
    rows = np.empty(size, dtype=np.int64)
    cols = np.empty(size, dtype=np.int64)
    lost = 0
    for i in range(ox.shape[0]):
        if not d[i] > 0.0:
            continue
        n = _arc_cells(ox[i], oy[i], alpha[i], half_fov[i], d[i], band[i], x0, y0, res,
                       n_rows, n_cols, rows, cols)
        m = 0
        for k in range(n):  # keep the candidates, in arc order
            r, c = rows[k], cols[k]
            if free[r, c] <= candidate_ratio * arcs[r, c]:
                rows[m] = r
                cols[m] = c
                m += 1
        if m == 0:
            lost += 1
            continue
        w = 1.0 / float(m) ** dilution
        for k in range(m):
            hits[rows[k], cols[k]] += w
    return lost


def empty_grid(shape: tuple[int, int]) -> F32:
    """A zeroed float32 evidence grid."""
    return np.zeros(shape, dtype=np.float32)
