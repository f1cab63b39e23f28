"""A group's free-space scans (ALGORITHM.md §3), packed, and their free-layer update, compiled.

Each scan's union of cones (:func:`.free_space.free_rows`) depends on the scan alone, not
on the map state, so it can be computed apart from (and before, or on another thread than)
the per-scan loop that merges and corrects features (:mod:`.andersone_scans`), and so can
the free layer's update (eq. 11 as integer counts per cell: a sum, the same in any order).

:class:`FreeUnions` packs the unions of scans ``k = 0 .. n − 1``: scan ``k``'s union is
``(row0, col0, col1)`` = ``head[k, :3]`` (``head[k, 3]`` its free cell count), its row
starts ``starts[row_cut[k] : row_cut[k + 1]]`` (indices into its own intervals) and its
intervals ``c0``/``c1[span_cut[k] : span_cut[k + 1]]`` (:func:`union_of`).

The default method also counts every free cone's cells once per reading (§9's ``free``,
:func:`.attribution.count_free`): the same cones' row spans, so :func:`free_unions` adds
them to a row difference grid while it has them, instead of rasterising the cones twice.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from pipeline.mapper.kernels.attribution import add_row_run
from pipeline.mapper.kernels.cone import cones_row_spans
from pipeline.mapper.kernels.free_space import union_of_spans

# No row difference grid to count into (:func:`free_unions`' ``diff``).
NO_COUNTS = np.zeros((0, 1), dtype=np.int32)


class FreeUnions(NamedTuple):
    """The packed unions of a group's scans (module docstring)."""

    head: np.ndarray  # (n, 4) int64: row0, col0, col1, free cell count
    row_cut: np.ndarray  # (n + 1,) int64
    starts: np.ndarray  # int64, per union relative to its own intervals
    span_cut: np.ndarray  # (n + 1,) int64
    c0: np.ndarray  # int64 grid columns, inclusive
    c1: np.ndarray


@njit(cache=True)
def _grown(a: np.ndarray, need: int) -> np.ndarray:
    """``a`` itself if it holds ``need`` values, else a copy at least twice as long."""
    if need <= a.shape[0]:
        return a
    out = np.empty(max(need, 2 * a.shape[0]), dtype=a.dtype)
    out[: a.shape[0]] = a
    return out


@njit(cache=True, nogil=True)
def free_unions(cones: np.ndarray, up_down: np.ndarray, cone_cut: np.ndarray, gx: float,
                gy: float, res: float, width: int, height: int,
                diff: np.ndarray) -> FreeUnions:
    """The union of cones ``cone_cut[k] : cone_cut[k + 1]`` for each scan ``k``, packed.

    Unless ``diff`` is :data:`NO_COUNTS` (no rows), every cone's cells are also counted
    once more in the row difference grid ``diff``: :func:`.attribution.count_free` of cones
    ``cone_cut[0] : cone_cut[-1]`` (integer adds: the same counts in any order).
    """
    counting = diff.shape[0] > 0
    n = cone_cut.shape[0] - 1
    head = np.zeros((n, 4), dtype=np.int64)
    row_cut = np.zeros(n + 1, dtype=np.int64)
    span_cut = np.zeros(n + 1, dtype=np.int64)
    starts = np.empty(1024, dtype=np.int64)
    c0 = np.empty(1024, dtype=np.int64)
    c1 = np.empty(1024, dtype=np.int64)
    for k in range(n):
        spans = cones_row_spans(cones, up_down, cone_cut[k], cone_cut[k + 1], gx, gy, res,
                                width, height)
        if counting:
            m, _, span_row, span_c0, span_c1 = spans[:5]
            for j in range(m):
                add_row_run(diff, span_row[j], span_c0[j], span_c1[j])
        row0, col0, col1, st, a0, a1, count = union_of_spans(*spans)
        head[k, 0] = row0
        head[k, 1] = col0
        head[k, 2] = col1
        head[k, 3] = count
        r, s = row_cut[k], span_cut[k]
        starts = _grown(starts, r + st.shape[0])
        starts[r : r + st.shape[0]] = st
        c0 = _grown(c0, s + a0.shape[0])
        c1 = _grown(c1, s + a0.shape[0])
        c0[s : s + a0.shape[0]] = a0
        c1[s : s + a0.shape[0]] = a1
        row_cut[k + 1] = r + st.shape[0]
        span_cut[k + 1] = s + a0.shape[0]
    return FreeUnions(head, row_cut, starts[: row_cut[n]], span_cut, c0[: span_cut[n]],
                      c1[: span_cut[n]])


@njit(cache=True)
def union_of(u: FreeUnions, k: int) -> tuple[int, int, int, np.ndarray, np.ndarray, np.ndarray,
                                             int]:
    """Scan ``k``'s union as :func:`.free_space.free_rows` returns it."""
    s0, s1 = u.span_cut[k], u.span_cut[k + 1]
    return (u.head[k, 0], u.head[k, 1], u.head[k, 2], u.starts[u.row_cut[k] : u.row_cut[k + 1]],
            u.c0[s0:s1], u.c1[s0:s1], u.head[k, 3])


@njit(cache=True, nogil=True)
def add_free_unions(diff: np.ndarray, u: FreeUnions) -> None:
    """Eq. 11 once for every free cell of every union: one more update in the row
    difference grid ``diff`` (``+1`` at each interval's first column, ``−1`` past its last;
    a union's intervals in a row do not overlap)."""
    for k in range(u.head.shape[0]):
        row0, _, _, starts, c0, c1, count = union_of(u, k)
        if count:
            for r in range(starts.shape[0] - 1):
                for i in range(starts[r], starts[r + 1]):
                    add_row_run(diff, row0 + r, c0[i], c1[i])
