"""One scan's free-space scan (ALGORITHM.md §3) as a window mask, compiled.

The compiled twin of :func:`pipeline.mapper.free_space.union_of_spans` over the cones of
:func:`pipeline.mapper.free_space.cone_spans`: each cone is rasterised row by row with
:mod:`.cone` (edges' sines and cosines given, computed by numpy as the reference does),
and the union is a boolean window over the spans' bounding box — the same window, the same
cells.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from pipeline.mapper.kernels.cone import cone_row_span, cone_rows


@njit(cache=True)
def free_window(cones: np.ndarray, up_down: np.ndarray, lo: int, hi: int, gx: float, gy: float,
                res: float, width: int, height: int) -> tuple[int, int, np.ndarray, int]:
    """The union of cones ``lo:hi``: ``(row0, col0, mask, free cell count)``.

    ``cones[k]`` = ``(ox, oy, radius, sin e1, cos e1, sin e2, cos e2)``, ``up_down[k]`` =
    whether the wedge holds +90°, −90°. An empty union is a ``(0, 0)`` mask.
    """
    n_rows = 0
    for k in range(lo, hi):
        r0, r1 = cone_rows(cones[k, 1], cones[k, 2], cones[k, 3], cones[k, 5], up_down[k, 0],
                           up_down[k, 1], gy, res, height)
        if r1 >= r0:
            n_rows += r1 - r0 + 1
    rows = np.empty(n_rows, dtype=np.int64)
    c0s = np.empty(n_rows, dtype=np.int64)
    c1s = np.empty(n_rows, dtype=np.int64)
    n = 0
    big = np.iinfo(np.int64).max
    row_lo, row_hi, col_lo, col_hi = big, -1, big, -1
    for k in range(lo, hi):
        ox, oy, radius = cones[k, 0], cones[k, 1], cones[k, 2]
        s1, c1, s2, c2 = cones[k, 3], cones[k, 4], cones[k, 5], cones[k, 6]
        r0, r1 = cone_rows(oy, radius, s1, s2, up_down[k, 0], up_down[k, 1], gy, res, height)
        for row in range(r0, r1 + 1):
            a, b = cone_row_span(ox, oy, radius, s1, c1, s2, c2, row, gx, gy, res, width)
            if a > b:
                continue
            rows[n] = row
            c0s[n] = a
            c1s[n] = b
            n += 1
            row_lo = min(row_lo, row)
            row_hi = max(row_hi, row)
            col_lo = min(col_lo, a)
            col_hi = max(col_hi, b)
    if n == 0:
        return 0, 0, np.zeros((0, 0), dtype=np.bool_), 0
    mask = np.zeros((row_hi - row_lo + 1, col_hi - col_lo + 1), dtype=np.bool_)
    count = 0
    for i in range(n):
        r = rows[i] - row_lo
        for c in range(c0s[i] - col_lo, c1s[i] - col_lo + 1):
            if not mask[r, c]:
                mask[r, c] = True
                count += 1
    return row_lo, col_lo, mask, count


@njit(cache=True)
def add_window(counts: np.ndarray, row0: int, col0: int, mask: np.ndarray) -> None:
    """Eq. 11 once for every free cell of the window: one more update in ``counts``."""
    h, w = mask.shape
    for r in range(h):
        for c in range(w):
            if mask[r, c]:
                counts[row0 + r, col0 + c] += 1
