"""A sonar cone on the grid, one reading at a time, as row spans (compiled).

The cell rule is that of :func:`pipeline.mapper.grid_raster.sector_spans`, computed with
the same arithmetic in the same order, so the two give the same cells bit for bit: a cell
(row r, col c) belongs to the sector when its centre lies within ``half_fov`` of the axis
``alpha`` (the intersection of the half-planes of the two cone edges) and within the row's
chord of the disk of radius ``r_outer`` (rows with ``dy² ≥ r_outer²`` are empty; a centre
exactly on the chord's end counts). With ``r_inner > 0`` cells whose centre is strictly
closer than ``r_inner`` are left out (the row's inner chord, open), which can split a
row in two spans. Spans are clipped to the grid.

Use from numba code::

    n = sector_spans(ox, oy, alpha, half_fov, r_inner, r_outer,
                     gx, gy, res, width, height, rows, c0s, c1s)
    for k in range(n):            # columns c0s[k]..c1s[k] (inclusive) of rows[k]
        ...

with buffers of at least :func:`max_sector_spans` ``(r_outer, res)`` entries. The lower
level :func:`edge_sector_spans`, :func:`cone_rows` and :func:`cone_row_span` take the edges'
sines and cosines precomputed (the mappers take them from numpy's
``grid_raster.cone_edges``, so their cones match the numpy reference on any CPU). This is
the mappers' one cone rasteriser: the andersone free space, the classic grid and the
attribution method's cones and echo arcs (:mod:`pipeline.mapper.kernels.attribution`) all use it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# As grid_raster._MAX_HALF_BEAM: half-widths of 90° and more are clamped just below it.
MAX_HALF_BEAM = 0.5 * math.pi - 1e-9


@njit(cache=True)
def wrap_angle(a: float) -> float:
    """``a`` wrapped to [−π, π), rad (``np.mod`` semantics, as grid_raster.wrap_angle)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True)
def cone_edges(alpha: float, half_fov: float) -> tuple[float, float, float, float, bool, bool]:
    """Sines and cosines of the edges ``α ∓ β/2`` and whether the wedge holds +90° / −90°."""
    hb = min(max(half_fov, 0.0), MAX_HALF_BEAM)
    e1 = alpha - hb
    e2 = alpha + hb
    up = abs(wrap_angle(0.5 * math.pi - alpha)) <= hb
    down = abs(wrap_angle(-0.5 * math.pi - alpha)) <= hb
    return math.sin(e1), math.cos(e1), math.sin(e2), math.cos(e2), up, down


@njit(cache=True)
def cone_rows(oy: float, radius: float, s1: float, s2: float, up: bool, down: bool,
              gy: float, res: float, height: int) -> tuple[int, int]:
    """First and last grid row (inclusive, clipped; empty when r1 < r0) of a sector's extent."""
    y1 = radius * s1
    y2 = radius * s2
    lo_y = min(0.0, min(y1, y2))
    hi_y = max(0.0, max(y1, y2))
    if up:
        hi_y = radius
    if down:
        lo_y = -radius
    r0 = math.ceil(((oy + lo_y) - gy) / res - 0.5)
    r1 = math.floor(((oy + hi_y) - gy) / res - 0.5)
    return min(max(r0, 0), height), min(max(r1, -1), height - 1)


@njit(cache=True)
def cone_row_chord(oy: float, radius: float, s1: float, c1: float, s2: float, c2: float,
                   row: int, gy: float, res: float) -> tuple[float, float, bool]:
    """The sector's x interval ``[lo, hi]`` (m, relative to the origin) on a row's centre line."""
    dy = (gy + (row + 0.5) * res) - oy
    h2 = radius * radius - dy * dy
    ok = h2 > 0
    h = math.sqrt(h2) if ok else 0.0
    lo = -h
    hi = h
    if s1 != 0.0:
        b1 = c1 * dy / s1
        if s1 > 0:
            hi = min(hi, b1)
        else:
            lo = max(lo, b1)
    elif c1 * dy < 0:
        ok = False
    if s2 != 0.0:
        b2 = c2 * dy / s2
        if s2 > 0:
            lo = max(lo, b2)
        else:
            hi = min(hi, b2)
    elif c2 * dy > 0:
        ok = False
    return lo, hi, ok


@njit(cache=True)
def columns_of(ox: float, lo: float, hi: float, gx: float, res: float) -> tuple[int, int]:
    """Columns (unclipped) whose centre x lies in ``[ox + lo, ox + hi]``."""
    c0 = math.ceil(((ox + lo) - gx) / res - 0.5)
    c1 = math.floor(((ox + hi) - gx) / res - 0.5)
    return c0, c1


@njit(cache=True)
def cone_row_span(ox: float, oy: float, radius: float, s1: float, c1: float, s2: float,
                  c2: float, row: int, gx: float, gy: float, res: float,
                  width: int) -> tuple[int, int]:
    """Columns ``c0..c1`` of the sector on ``row``, clipped to the grid; empty when c0 > c1."""
    lo, hi, ok = cone_row_chord(oy, radius, s1, c1, s2, c2, row, gy, res)
    if not ok:
        return 0, -1
    a, b = columns_of(ox, lo, hi, gx, res)
    if not (a <= b and b >= 0 and a <= width - 1):
        return 0, -1
    return min(max(a, 0), width - 1), min(max(b, 0), width - 1)


@njit(cache=True, error_model="numpy")
def cone_row_spans(ox: float, oy: float, radius: float, s1: float, c1: float, s2: float,
                   c2: float, r0: int, r1: int, gx: float, gy: float, res: float, width: int,
                   a_out: np.ndarray, b_out: np.ndarray) -> None:
    """:func:`cone_row_span` of rows ``r0 .. r1`` into ``a_out[j], b_out[j]`` (row
    ``r0 + j``; empty when ``a > b``): the same operations in a loop without branches, so the
    compiler computes several rows at once (their square roots and divisions), the same
    bits as row by row."""
    flip1 = s1 > 0  # which side each edge bounds is fixed by the cone
    flip2 = s2 > 0
    for j in range(r1 - r0 + 1):
        dy = (gy + ((r0 + j) + 0.5) * res) - oy
        h2 = radius * radius - dy * dy
        ok = h2 > 0
        h = math.sqrt(max(h2, 0.0))  # any value where not ok: the row is empty
        lo = -h
        hi = h
        b1 = c1 * dy / s1 if s1 != 0.0 else 0.0
        b2 = c2 * dy / s2 if s2 != 0.0 else 0.0
        if s1 != 0.0:
            hi = min(hi, b1) if flip1 else hi
            lo = lo if flip1 else max(lo, b1)
        else:
            ok = ok and not c1 * dy < 0
        if s2 != 0.0:
            lo = max(lo, b2) if flip2 else lo
            hi = hi if flip2 else min(hi, b2)
        else:
            ok = ok and not c2 * dy > 0
        a = math.ceil(((ox + lo) - gx) / res - 0.5)
        b = math.floor(((ox + hi) - gx) / res - 0.5)
        ok = ok and a <= b and b >= 0 and a <= width - 1
        a_out[j] = min(max(a, 0), width - 1) if ok else 0
        b_out[j] = min(max(b, 0), width - 1) if ok else -1


@njit(cache=True)
def max_sector_spans(r_outer: float, res: float) -> int:
    """An upper bound of the spans :func:`sector_spans` writes for a sector of radius ``r_outer``."""
    return 2 * (math.ceil(2.0 * r_outer / res) + 3)


@njit(cache=True)
def sector_spans(ox: float, oy: float, alpha: float, half_fov: float, r_inner: float,
                 r_outer: float, gx: float, gy: float, res: float, width: int, height: int,
                 rows: np.ndarray, c0s: np.ndarray, c1s: np.ndarray) -> int:
    """Write the spans of the sector ``r_inner ≤ dist < r_outer``, ``|bearing − α| ≤ β/2``
    (module doc for the exact rule) into ``rows, c0s, c1s``; returns how many, by row."""
    if not r_outer > 0.0:
        return 0
    s1, c1, s2, c2, up, down = cone_edges(alpha, half_fov)
    return edge_sector_spans(ox, oy, s1, c1, s2, c2, up, down, r_inner, r_outer, gx, gy, res,
                             width, height, rows, c0s, c1s)


@njit(cache=True)
def edge_sector_spans(ox: float, oy: float, s1: float, c1: float, s2: float, c2: float,
                      up: bool, down: bool, r_inner: float, r_outer: float, gx: float,
                      gy: float, res: float, width: int, height: int, rows: np.ndarray,
                      c0s: np.ndarray, c1s: np.ndarray) -> int:
    """:func:`sector_spans` with the edges' sines and cosines given (:func:`cone_edges`, or
    numpy's ``grid_raster.cone_edges``)."""
    n = 0
    if not r_outer > 0.0:
        return 0
    r0, r1 = cone_rows(oy, r_outer, s1, s2, up, down, gy, res, height)
    rin2 = r_inner * r_inner if r_inner > 0.0 else 0.0
    if rin2 > 0.0:
        # Only rows the annulus part reaches: its y extent is set by the four corners
        # (radii × edges) and ±r_outer when the wedge holds ±90°. One row of margin on
        # each side: the rows visited compute their spans as before, so skipping rows
        # that cannot hold a cell changes nothing.
        lo_y = min(min(r_inner * s1, r_inner * s2), min(r_outer * s1, r_outer * s2))
        hi_y = max(max(r_inner * s1, r_inner * s2), max(r_outer * s1, r_outer * s2))
        if up:
            hi_y = r_outer
        if down:
            lo_y = -r_outer
        r0 = max(r0, math.ceil(((oy + lo_y) - gy) / res - 0.5) - 1)
        r1 = min(r1, math.floor(((oy + hi_y) - gy) / res - 0.5) + 1)
    m = r1 - r0 + 1
    if m <= 0:
        return 0
    # The rows' outer spans at once, at the buffers' end: row r0 + j is read before the
    # spans written so far (at most 2j + 2 < size − m + j + 1, as m ≤ size / 2) reach it.
    base = rows.shape[0] - m
    cone_row_spans(ox, oy, r_outer, s1, c1, s2, c2, r0, r1, gx, gy, res, width, c0s[base:],
                   c1s[base:])
    for row in range(r0, r1 + 1):
        a, b = c0s[base + row - r0], c1s[base + row - r0]
        if a > b:
            continue
        dy = (gy + (row + 0.5) * res) - oy
        h2 = rin2 - dy * dy
        if h2 > 0:
            # Columns strictly inside the inner chord (ox − h, ox + h) are left out.
            h = math.sqrt(h2)
            e0 = math.floor(((ox - h) - gx) / res - 0.5) + 1
            e1 = math.ceil(((ox + h) - gx) / res - 0.5) - 1
            if e0 <= e1 and e1 >= a and e0 <= b:
                if e0 > a:
                    rows[n] = row
                    c0s[n] = a
                    c1s[n] = e0 - 1
                    n += 1
                if e1 < b:
                    rows[n] = row
                    c0s[n] = e1 + 1
                    c1s[n] = b
                    n += 1
                continue
        rows[n] = row
        c0s[n] = a
        c1s[n] = b
        n += 1
    return n


@njit(cache=True)
def cones_row_spans(cones: np.ndarray, up_down: np.ndarray, lo: int, hi: int, gx: float,
                    gy: float, res: float, width: int, height: int
                    ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                               int, int, int, int]:
    """The row spans of cones ``lo:hi`` (whole cones, out to ``radius``) and their box.

    ``cones[k]`` = ``(ox, oy, radius, sin e1, cos e1, sin e2, cos e2)``, ``up_down[k]`` =
    whether the wedge holds +90°, −90°. Returns ``(n, owner, rows, c0s, c1s, row_lo,
    row_hi, col_lo, col_hi)``: span ``j < n`` is row ``rows[j]``, columns ``c0s[j] ..
    c1s[j]`` of cone ``owner[j]``; the box is empty (``row_hi = −1``) when ``n = 0``.
    """
    n_rows = 0
    for k in range(lo, hi):
        r0, r1 = cone_rows(cones[k, 1], cones[k, 2], cones[k, 3], cones[k, 5], up_down[k, 0],
                           up_down[k, 1], gy, res, height)
        if r1 >= r0:
            n_rows += r1 - r0 + 1
    owner = np.empty(n_rows, dtype=np.int64)
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
        if r1 < r0:
            continue
        # The cone's rows written after the spans kept so far, then kept in place.
        cone_row_spans(ox, oy, radius, s1, c1, s2, c2, r0, r1, gx, gy, res, width, c0s[n:],
                       c1s[n:])
        first = n
        for row in range(r0, r1 + 1):
            a, b = c0s[first + row - r0], c1s[first + row - r0]
            if a > b:
                continue
            owner[n] = k
            rows[n] = row
            c0s[n] = a
            c1s[n] = b
            n += 1
            row_lo = min(row_lo, row)
            row_hi = max(row_hi, row)
            col_lo = min(col_lo, a)
            col_hi = max(col_hi, b)
    return n, owner, rows, c0s, c1s, row_lo, row_hi, col_lo, col_hi
