"""The classic grid's per-scan update (ALGORITHM.md §8), compiled.

The compiled twin of :meth:`pipeline.mapper.classic.ClassicMapper` 's numpy reference: each
cone is rasterised out to its far edge (``d + w/2``, or ``r_max`` for a clearing max-range
reading) with :mod:`.cone`; a cell of an echo's cone is occupied when
``|dist − d| ≤ w/2`` and free when ``dist < d − w/2`` (every cell of a clearing cone is
free); within a scan a cell gets one update, occupied winning over free; the update is
the reference's float32 log-odds add and clamp. A cone's row spans are computed for all
its rows at once (:func:`~pipeline.mapper.kernels.cone.cone_row_spans`, the same bits).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from pipeline.mapper.kernels.cone import cones_row_spans

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
    for k in range(cone_cut.shape[0] - 1):
        lo, hi = cone_cut[k], cone_cut[k + 1]
        n, owner, rows, c0s, c1s, row_lo, row_hi, col_lo, col_hi = cones_row_spans(
            cones, up_down, lo, hi, gx, gy, res, width, height)
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
