"""The classic grid's per-scan update (ALGORITHM.md §8), compiled.

The compiled twin of :meth:`pipeline.mapper.classic.ClassicMapper` 's numpy reference: each
cone is rasterised out to its far edge (``d + w/2``, or ``r_max`` for a clearing max-range
reading) with :mod:`.cone`; a cell of an echo's cone is occupied when
``|dist − d| ≤ w/2`` and free when ``dist < d − w/2`` (every cell of a clearing cone is
free); within a scan a cell gets one update, occupied winning over free; the update is
the reference's float32 log-odds add and clamp.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from pipeline.mapper.kernels.cone import cone_row_span, cone_rows

_NONE, _FREE, _OCC = 0, 1, 2


@njit(cache=True)
def classic_scans(cones: np.ndarray, up_down: np.ndarray, ranges: np.ndarray, echo: np.ndarray,
                  cone_cut: np.ndarray, half_w: float, gx: float, gy: float, res: float,
                  width: int, height: int, l_free: np.float32, l_occ: np.float32,
                  l_min: np.float32, l_max: np.float32, logodds: np.ndarray,
                  touched: np.ndarray) -> int:
    """Update ``logodds`` (float32) and ``touched`` for scans ``k`` = cones
    ``cone_cut[k]:cone_cut[k+1]``; returns the number of free updates (cells_freed)."""
    freed = 0
    big = np.iinfo(np.int64).max
    for k in range(cone_cut.shape[0] - 1):
        lo, hi = cone_cut[k], cone_cut[k + 1]
        row_lo, row_hi, col_lo, col_hi = big, -1, big, -1
        for i in range(lo, hi):
            ox, oy, radius = cones[i, 0], cones[i, 1], cones[i, 2]
            s1, c1, s2, c2 = cones[i, 3], cones[i, 4], cones[i, 5], cones[i, 6]
            r0, r1 = cone_rows(oy, radius, s1, s2, up_down[i, 0], up_down[i, 1], gy, res, height)
            for row in range(r0, r1 + 1):
                a, b = cone_row_span(ox, oy, radius, s1, c1, s2, c2, row, gx, gy, res, width)
                if a <= b:
                    row_lo = min(row_lo, row)
                    row_hi = max(row_hi, row)
                    col_lo = min(col_lo, a)
                    col_hi = max(col_hi, b)
        if row_hi < 0:
            continue
        state = np.zeros((row_hi - row_lo + 1, col_hi - col_lo + 1), dtype=np.int8)
        for i in range(lo, hi):
            ox, oy, radius = cones[i, 0], cones[i, 1], cones[i, 2]
            s1, c1, s2, c2 = cones[i, 3], cones[i, 4], cones[i, 5], cones[i, 6]
            d = ranges[i]
            r0, r1 = cone_rows(oy, radius, s1, s2, up_down[i, 0], up_down[i, 1], gy, res, height)
            for row in range(r0, r1 + 1):
                a, b = cone_row_span(ox, oy, radius, s1, c1, s2, c2, row, gx, gy, res, width)
                dy = (gy + (row + 0.5) * res) - oy
                for c in range(a, b + 1):
                    if echo[i]:
                        dist = math.hypot((gx + (c + 0.5) * res) - ox, dy)
                        if abs(dist - d) <= half_w:
                            code = _OCC
                        elif dist < d - half_w:
                            code = _FREE
                        else:
                            code = _NONE
                    else:
                        code = _FREE
                    cell = state[row - row_lo, c - col_lo]
                    if code > cell:
                        state[row - row_lo, c - col_lo] = code
        h, w = state.shape
        for r in range(h):
            for c in range(w):
                code = state[r, c]
                if code == _NONE:
                    continue
                step = l_occ if code == _OCC else l_free
                v = logodds[row_lo + r, col_lo + c] + step
                logodds[row_lo + r, col_lo + c] = min(max(v, l_min), l_max)
                touched[row_lo + r, col_lo + c] = True
                if code == _FREE:
                    freed += 1
    return freed
