"""One scan's free-space scan (ALGORITHM.md §3) as merged row intervals, compiled.

The compiled twin of :func:`pipeline.mapper.free_space.union_of_spans` over the cones of
:func:`pipeline.mapper.free_space.cone_spans`: each cone is rasterised row by row with
:mod:`.cone` (edges' sines and cosines given, computed by numpy as the reference does);
the union is kept as each row's disjoint, sorted column intervals (spans bucketed by row,
sorted by first column, overlapping or touching spans merged). The same cells as the
reference's window mask, without a window: the work is O(spans + free cells), not
O(bounding box) — a ring of sonars has a box several times its cones' area.

A union is ``(row0, col0, col1, starts, c0, c1)``: rows ``row0 .. row0 + len(starts) − 2``;
row ``row0 + r`` holds the intervals ``starts[r] .. starts[r + 1] − 1`` of ``c0``/``c1``
(grid columns, inclusive); ``col0..col1`` is the columns' extent (the reference window's).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from pipeline.mapper.kernels.cone import cones_row_spans


@njit(cache=True)
def free_rows(cones: np.ndarray, up_down: np.ndarray, lo: int, hi: int, gx: float, gy: float,
              res: float, width: int,
              height: int) -> tuple[int, int, int, np.ndarray, np.ndarray, np.ndarray, int]:
    """The union of cones ``lo:hi`` and its free cell count (an empty union has no rows).

    ``cones[k]`` = ``(ox, oy, radius, sin e1, cos e1, sin e2, cos e2)``, ``up_down[k]`` =
    whether the wedge holds +90°, −90°.
    """
    return union_of_spans(*cones_row_spans(cones, up_down, lo, hi, gx, gy, res, width, height))


@njit(cache=True)
def union_of_spans(n: int, owner: np.ndarray, rows: np.ndarray, c0s: np.ndarray,
                   c1s: np.ndarray, row_lo: int, row_hi: int, col_lo: int, col_hi: int
                   ) -> tuple[int, int, int, np.ndarray, np.ndarray, np.ndarray, int]:
    """:func:`free_rows` of the row spans :func:`.cone.cones_row_spans` returns (which it
    leaves as they are)."""
    if n == 0:
        empty = np.zeros(0, dtype=np.int64)
        return 0, 0, -1, np.zeros(1, dtype=np.int64), empty, empty, 0
    h = row_hi - row_lo + 1
    # Bucket the spans by row (counting sort), then per row: sort by first column, merge.
    starts = np.zeros(h + 1, dtype=np.int64)
    for i in range(n):
        starts[rows[i] - row_lo + 1] += 1
    for r in range(h):
        starts[r + 1] += starts[r]
    fill = starts[:-1].copy()
    a0 = np.empty(n, dtype=np.int64)
    a1 = np.empty(n, dtype=np.int64)
    for i in range(n):
        r = rows[i] - row_lo
        a0[fill[r]] = c0s[i]
        a1[fill[r]] = c1s[i]
        fill[r] += 1
    m = 0
    count = 0
    for r in range(h):
        s, e = starts[r], starts[r + 1]
        for i in range(s + 1, e):  # insertion sort: a row holds a few spans
            x0, x1 = a0[i], a1[i]
            j = i - 1
            while j >= s and a0[j] > x0:
                a0[j + 1] = a0[j]
                a1[j + 1] = a1[j]
                j -= 1
            a0[j + 1] = x0
            a1[j + 1] = x1
        starts[r] = m
        i = s
        while i < e:
            x0, x1 = a0[i], a1[i]
            i += 1
            while i < e and a0[i] <= x1 + 1:
                x1 = max(x1, a1[i])
                i += 1
            a0[m] = x0  # m <= the read position: merging in place is safe
            a1[m] = x1
            m += 1
            count += x1 - x0 + 1
    starts[h] = m
    return row_lo, col_lo, col_hi, starts, a0[:m], a1[:m], count


@njit(cache=True)
def is_free(starts: np.ndarray, c0: np.ndarray, c1: np.ndarray, r: int, col: int) -> bool:
    """Whether grid column ``col`` of union row ``r`` (0 = the union's first row) is free."""
    if r < 0 or r >= starts.shape[0] - 1:
        return False
    for i in range(starts[r], starts[r + 1]):
        if col < c0[i]:
            return False
        if col <= c1[i]:
            return True
    return False


@njit(cache=True)
def any_free(starts: np.ndarray, c0: np.ndarray, c1: np.ndarray, r: int, a: int, b: int) -> bool:
    """Whether union row ``r`` has a free cell among grid columns ``a..b``."""
    if r < 0 or r >= starts.shape[0] - 1 or a > b:
        return False
    for i in range(starts[r], starts[r + 1]):
        if c0[i] > b:
            return False
        if c1[i] >= a:
            return True
    return False
