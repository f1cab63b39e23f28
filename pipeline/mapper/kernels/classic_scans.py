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
    ``cone_cut[k]:cone_cut[k+1]``; returns the number of free updates (cells_freed).

    Per scan: the cones' spans (kept), each cell's class (occupied > free > none, the
    highest over the scan's cones) in a window over their bounding box, then one update
    per classified cell, walking the spans again (the window is reset as it goes).
    """
    freed = 0
    big = np.iinfo(np.int64).max
    for k in range(cone_cut.shape[0] - 1):
        lo, hi = cone_cut[k], cone_cut[k + 1]
        n_rows = 0
        for i in range(lo, hi):
            r0, r1 = cone_rows(cones[i, 1], cones[i, 2], cones[i, 3], cones[i, 5],
                               up_down[i, 0], up_down[i, 1], gy, res, height)
            if r1 >= r0:
                n_rows += r1 - r0 + 1
        owner = np.empty(n_rows, dtype=np.int64)
        rows = np.empty(n_rows, dtype=np.int64)
        c0s = np.empty(n_rows, dtype=np.int64)
        c1s = np.empty(n_rows, dtype=np.int64)
        n = 0
        row_lo, row_hi, col_lo, col_hi = big, -1, big, -1
        for i in range(lo, hi):
            ox, oy, radius = cones[i, 0], cones[i, 1], cones[i, 2]
            s1, c1, s2, c2 = cones[i, 3], cones[i, 4], cones[i, 5], cones[i, 6]
            r0, r1 = cone_rows(oy, radius, s1, s2, up_down[i, 0], up_down[i, 1], gy, res, height)
            for row in range(r0, r1 + 1):
                a, b = cone_row_span(ox, oy, radius, s1, c1, s2, c2, row, gx, gy, res, width)
                if a <= b:
                    owner[n] = i
                    rows[n] = row
                    c0s[n] = a
                    c1s[n] = b
                    n += 1
                    row_lo = min(row_lo, row)
                    row_hi = max(row_hi, row)
                    col_lo = min(col_lo, a)
                    col_hi = max(col_hi, b)
        if n == 0:
            continue
        state = np.zeros((row_hi - row_lo + 1, col_hi - col_lo + 1), dtype=np.int8)
        for j in range(n):
            i = owner[j]
            row = rows[j]
            ox, oy, d = cones[i, 0], cones[i, 1], ranges[i]
            dy = (gy + (row + 0.5) * res) - oy
            for c in range(c0s[j], c1s[j] + 1):
                if echo[i]:
                    dx = (gx + (c + 0.5) * res) - ox
                    dist = math.sqrt(dx * dx + dy * dy)
                    if abs(dist - d) <= half_w:
                        code = _OCC
                    elif dist < d - half_w:
                        code = _FREE
                    else:
                        code = _NONE
                else:
                    code = _FREE
                if code > state[row - row_lo, c - col_lo]:
                    state[row - row_lo, c - col_lo] = code
        for j in range(n):
            row = rows[j]
            for c in range(c0s[j], c1s[j] + 1):
                code = state[row - row_lo, c - col_lo]
                if code == _NONE:
                    continue
                state[row - row_lo, c - col_lo] = _NONE  # one update per cell and scan
                step = l_occ if code == _OCC else l_free
                v = logodds[row, c] + step
                logodds[row, c] = min(max(v, l_min), l_max)
                touched[row, c] = True
                if code == _FREE:
                    freed += 1
    return freed
