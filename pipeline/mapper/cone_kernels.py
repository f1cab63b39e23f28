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
def _col_range(
    ox: float, a: float, hf: float, r: float, dy: float, x0: float, res: float, n_cols: int
) -> tuple[int, int]:
    """Columns of one row (centre offset ``dy`` from the origin) that may hold sector cells:
    the outer disk's chord clipped to the sector's x extent."""
    h2 = r * r - dy * dy
    if h2 < 0.0:
        return 0, -1
    h = math.sqrt(h2)
    lo = min(0.0, r * math.cos(a - hf), r * math.cos(a + hf))
    hi = max(0.0, r * math.cos(a - hf), r * math.cos(a + hf))
    if abs((-a + math.pi) % (2 * math.pi) - math.pi) <= hf:
        hi = r
    if abs((math.pi - a + math.pi) % (2 * math.pi) - math.pi) <= hf:
        lo = -r
    lo = max(lo, -h)
    hi = min(hi, h)
    c0 = max(math.floor((ox + lo - x0) / res - 0.5), 0)
    c1 = min(math.ceil((ox + hi - x0) / res - 0.5), n_cols - 1)
    return c0, c1


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
        ca, sa, ch = math.cos(alpha[i]), math.sin(alpha[i]), math.cos(hf)
        r2 = r * r
        r0, r1 = _row_range(oy[i], alpha[i], hf, r, y0, res, n_rows)
        for row in range(r0, r1 + 1):
            dy = y0 + (row + 0.5) * res - oy[i]
            c0, c1 = _col_range(ox[i], alpha[i], hf, r, dy, x0, res, n_cols)
            for col in range(c0, c1 + 1):
                dx = x0 + (col + 0.5) * res - ox[i]
                d2 = dx * dx + dy * dy
                if d2 >= r2 or dx * ca + dy * sa < math.sqrt(d2) * ch:
                    continue
                counts[row, col] += 1.0
                total += 1
    return total


@njit(cache=True)
def count_arcs(
    ox: F64, oy: F64, alpha: F64, half_fov: F64, d: F64, band: F64,
    x0: float, y0: float, res: float, counts: F32,
) -> None:
    """Add 1 to ``counts`` at every cell of every echo's arc: in the cone, at a distance
    within ``d ± band`` of the origin (inclusive). Readings with ``d ≤ 0`` have no arc."""
    n_rows, n_cols = counts.shape
    for i in range(ox.shape[0]):
        if not d[i] > 0.0:
            continue
        ro = d[i] + band[i]
        ri = max(d[i] - band[i], 0.0)
        hf = min(max(half_fov[i], 0.0), _MAX_HALF_BEAM)
        ca, sa, ch = math.cos(alpha[i]), math.sin(alpha[i]), math.cos(hf)
        r0, r1 = _row_range(oy[i], alpha[i], hf, ro, y0, res, n_rows)
        for row in range(r0, r1 + 1):
            dy = y0 + (row + 0.5) * res - oy[i]
            c0, c1 = _col_range(ox[i], alpha[i], hf, ro, dy, x0, res, n_cols)
            for col in range(c0, c1 + 1):
                dx = x0 + (col + 0.5) * res - ox[i]
                d2 = dx * dx + dy * dy
                if d2 > ro * ro or d2 < ri * ri or dx * ca + dy * sa < math.sqrt(d2) * ch:
                    continue
                counts[row, col] += 1.0


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
    lost = 0
    for i in range(ox.shape[0]):
        if not d[i] > 0.0:
            continue
        ro = d[i] + band[i]
        ri = max(d[i] - band[i], 0.0)
        hf = min(max(half_fov[i], 0.0), _MAX_HALF_BEAM)
        ca, sa, ch = math.cos(alpha[i]), math.sin(alpha[i]), math.cos(hf)
        r0, r1 = _row_range(oy[i], alpha[i], hf, ro, y0, res, n_rows)
        n = 0
        for sweep in range(2):
            w = 0.0 if n == 0 else 1.0 / float(n) ** dilution
            for row in range(r0, r1 + 1):
                dy = y0 + (row + 0.5) * res - oy[i]
                c0, c1 = _col_range(ox[i], alpha[i], hf, ro, dy, x0, res, n_cols)
                for col in range(c0, c1 + 1):
                    dx = x0 + (col + 0.5) * res - ox[i]
                    d2 = dx * dx + dy * dy
                    if d2 > ro * ro or d2 < ri * ri or dx * ca + dy * sa < math.sqrt(d2) * ch:
                        continue
                    if free[row, col] > candidate_ratio * arcs[row, col]:
                        continue
                    if sweep == 0:
                        n += 1
                    else:
                        hits[row, col] += w
            if n == 0:
                lost += 1
                break
    return lost


def empty_grid(shape: tuple[int, int]) -> F32:
    """A zeroed float32 evidence grid."""
    return np.zeros(shape, dtype=np.float32)
