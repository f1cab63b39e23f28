"""Compiled per-reading loops of the attribution method (§9) over sonar cones and echo arcs.

Cones and arcs are rasterised by the mappers' one cone rasteriser,
:mod:`pipeline.mapper.kernels.cone` (the cell rule of
:func:`pipeline.mapper.grid_raster.sector_spans`: a cell belongs to a shape when its centre
does), from the table :func:`pipeline.mapper.free_space.cone_table` builds: ``cones[k]`` =
``(ox, oy, r_outer, sin e1, cos e1, sin e2, cos e2)``, ``up_down[k]`` = whether the wedge
holds +90° / −90°. The free cones are the andersone mapper's own cones, cell for cell. An
echo's arc is the annular sector ``r_inner ≤ dist ≤ r_outer`` (``d ∓ band``).

Loops run in reading order and add in that order, so results are deterministic.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from pipeline.mapper.kernels.cone import (
    cone_row_spans,
    cone_rows,
    edge_sector_spans,
    max_sector_spans,
)
from pipeline.mapper.types import F32, F64, I32, B


@njit(cache=True)
def count_free(cones: F64, up_down: B, gx: float, gy: float, res: float, diff: I32) -> int:
    """Count every cell of every cone once more (one count per reading, not per scan) in
    the row difference grid ``diff`` (:func:`empty_span_counts`); returns the cells added."""
    height, width = diff.shape[0], diff.shape[1] - 1
    total = 0
    a_buf = np.empty(reach_cells(cones, res), dtype=np.int64)  # a cone's rows
    b_buf = np.empty_like(a_buf)
    for i in range(cones.shape[0]):
        ox, oy, radius = cones[i, 0], cones[i, 1], cones[i, 2]
        s1, c1, s2, c2 = cones[i, 3], cones[i, 4], cones[i, 5], cones[i, 6]
        r0, r1 = cone_rows(oy, radius, s1, s2, up_down[i, 0], up_down[i, 1], gy, res, height)
        cone_row_spans(ox, oy, radius, s1, c1, s2, c2, r0, r1, gx, gy, res, width, a_buf, b_buf)
        for row in range(r0, r1 + 1):
            a, b = a_buf[row - r0], b_buf[row - r0]
            if b >= a:
                add_row_run(diff, row, a, b)
                total += b - a + 1
    return total


@njit(cache=True, inline="always")
def add_row_run(diff: I32, row: int, c0: int, c1: int) -> None:
    """One more count for cells ``c0 .. c1`` of ``row`` in the row difference grid ``diff``
    (:func:`empty_span_counts`): +1 at ``c0``, −1 past ``c1``."""
    diff[row, c0] += 1
    diff[row, c1 + 1] -= 1


@njit(cache=True)
def reach_cells(cones: F64, res: float) -> int:
    """Cells across the bounding box of the table's largest cone."""
    reach = 0.0
    for i in range(cones.shape[0]):
        reach = max(reach, cones[i, 2])
    return 2 * math.ceil(reach / res) + 3


@njit(cache=True)
def span_buffers(cones: F64, res: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Span buffers large enough for the widest arc of the table."""
    size = max_sector_spans(reach_cells(cones, res) * res, res)
    return (np.empty(size, dtype=np.int64), np.empty(size, dtype=np.int64),
            np.empty(size, dtype=np.int64))


@njit(cache=True, inline="always")
def spread_echo(hits: F32, cand_r: np.ndarray, cand_c: np.ndarray, m: int,
                dilution: float) -> None:
    """Spread one echo over its ``m`` candidate cells: ``1 / m ** dilution`` each."""
    w = 1.0 / float(m) ** dilution
    for k in range(m):
        hits[cand_r[k], cand_c[k]] += w


@njit(cache=True, inline="always")
def _arc_spans(cones: F64, up_down: B, r_inner: F64, i: int, gx: float, gy: float,
               res: float, width: int, height: int, rows: np.ndarray, c0s: np.ndarray,
               c1s: np.ndarray) -> int:
    return edge_sector_spans(cones[i, 0], cones[i, 1], cones[i, 3], cones[i, 4], cones[i, 5],
                             cones[i, 6], up_down[i, 0], up_down[i, 1], r_inner[i],
                             cones[i, 2], gx, gy, res, width, height, rows, c0s, c1s)


@njit(cache=True)
def count_arcs(cones: F64, up_down: B, r_inner: F64, gx: float, gy: float, res: float,
               diff: I32) -> None:
    """Count every cell of every echo's arc (``r_inner[k]`` to ``cones[k, 2]``) once more in
    the row difference grid ``diff`` (:func:`empty_span_counts`)."""
    height, width = diff.shape[0], diff.shape[1] - 1
    rows, c0s, c1s = span_buffers(cones, res)
    for i in range(cones.shape[0]):
        n = _arc_spans(cones, up_down, r_inner, i, gx, gy, res, width, height, rows, c0s, c1s)
        for k in range(n):
            add_row_run(diff, rows[k], c0s[k], c1s[k])


@njit(cache=True)
def attribute_echoes(cones: F64, up_down: B, r_inner: F64, gx: float, gy: float, res: float,
                     free: F32, arcs: F32, candidate_ratio: float, dilution: float,
                     hits: F32) -> int:
    """Spread each echo over the cells of its arc that may have produced it; returns the
    echoes with no such cell.

    A cell of the arc is a *candidate* unless the free-space evidence rules it out:
    ``free > candidate_ratio · arcs`` (it was seen free more often, by that factor, than
    echo arcs cover it). Each of the ``n`` candidates gets ``1 / n**dilution`` of the echo.
    """
    height, width = hits.shape
    rows, c0s, c1s = span_buffers(cones, res)
    size = reach_cells(cones, res) ** 2
    cand_r = np.empty(size, dtype=np.int64)
    cand_c = np.empty(size, dtype=np.int64)
    lost = 0
    for i in range(cones.shape[0]):
        n = _arc_spans(cones, up_down, r_inner, i, gx, gy, res, width, height, rows, c0s, c1s)
        m = 0
        for k in range(n):  # keep the candidates, in arc order
            r = rows[k]
            for c in range(c0s[k], c1s[k] + 1):
                if free[r, c] <= candidate_ratio * arcs[r, c]:
                    cand_r[m] = r
                    cand_c[m] = c
                    m += 1
        if m == 0:
            lost += 1
            continue
        spread_echo(hits, cand_r, cand_c, m, dilution)
    return lost


def empty_grid(shape: tuple[int, int]) -> F32:
    """A zeroed float32 evidence grid."""
    return np.zeros(shape, dtype=np.float32)


def empty_span_counts(shape: tuple[int, int]) -> I32:
    """A zeroed row difference grid for :func:`count_free` / :func:`count_arcs`: a span
    ``c0..c1`` of a row adds 1 at ``c0`` and −1 at ``c1 + 1`` (one spare column), so a count
    costs per span, not per cell; :func:`span_counts` turns it into counts per cell."""
    return np.zeros((shape[0], shape[1] + 1), dtype=np.int32)


def span_counts(diff: I32) -> F32:
    """Counts per cell of a row difference grid (its running sum along each row), float32
    as the evidence grids; ``diff`` is overwritten. Exact up to 2**24 counts per cell."""
    np.cumsum(diff, axis=1, dtype=np.int32, out=diff)
    return diff[:, :-1].astype(np.float32)
