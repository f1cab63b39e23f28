"""An attribution pass's echoes split in two: their candidates listed, then spread in order.

:func:`~pipeline.mapper.kernels.specular.trace_readings` (``attribute``) finds each echo's
candidate cells (reading the free and arc counts, which the pass does not change) and spreads
the echo over them (adding to the hits), reading by reading. The search does not depend on
the hits, so one thread may list the candidates of the last readings of a group
(:func:`echo_candidate_lists`) while another traces the first ones; spreading the lists after
them (:func:`spread_candidate_lists`) adds the same values to the same cells in the same
order: the same bits. The arcs' row spans are :mod:`.cone`'s (a cone's rows at once:
:func:`~pipeline.mapper.kernels.cone.cone_row_spans`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from pipeline.mapper.kernels.attribution import reach_cells, span_buffers
from pipeline.mapper.kernels.free_unions import _grown
from pipeline.mapper.kernels.specular import echo_candidates
from pipeline.mapper.types import F32, F64, I32, I64, B


@njit(cache=True, nogil=True, error_model="numpy")
def echo_candidate_lists(
    cones: F64, up_down: B, r_inner: F64, alpha: F64, half_fov: F64, gx: float, gy: float,
    res: float, offsets: I64, stops: F64, stopped_in: B, free_in: F32, arcs_in: F32,
    ratio: float, lo: int, hi: int,
) -> tuple[I64, I32]:
    """The echo candidates (no bearings) of readings ``lo:hi``: ``(cut, cells)``, reading
    ``lo + j``'s are ``cells[cut[j]:cut[j + 1]]`` (none for a reading with no echo), as
    grid cells ``row · width + column`` (int32: a grid holds fewer than 2³¹ cells).

    Speed, not results: each reading's search fills a small buffer that stays in cache (as
    :func:`~pipeline.mapper.kernels.specular.trace_readings`' does) and only its cells are
    kept, 4 bytes each: half the listing's time of writing every search into the growing
    lists as (row, column) int64 pairs."""
    height, width = free_in.shape
    rows, c0s, c1s = span_buffers(cones, res)
    most = reach_cells(cones, res) ** 2  # a reading's candidates at most
    cand_r = np.empty(most, dtype=np.int64)
    cand_c = np.empty(most, dtype=np.int64)
    cut = np.zeros(hi - lo + 1, dtype=np.int64)
    cells = np.empty(max(1024, 16 * (hi - lo)), dtype=np.int32)
    for j in range(hi - lo):
        m = echo_candidates(cones, up_down, r_inner, alpha, half_fov, lo + j, gx, gy, res,
                            width, height, offsets, stops, stopped_in, False, free_in,
                            free_in, free_in, arcs_in, ratio, rows, c0s, c1s, cand_r, cand_c)
        k = cut[j]
        cells = _grown(cells, k + m)
        for q in range(m):
            cells[k + q] = cand_r[q] * width + cand_c[q]
        cut[j + 1] = k + m
    return cut, cells[: cut[-1]]


@njit(cache=True, nogil=True)
def spread_candidate_lists(hits: F32, cut: I64, cells: I32, dilution: float) -> int:
    """Spread each listed echo over its candidate cells (``row · width + column``) in order
    (``1 / m ** dilution`` each, as :func:`~pipeline.mapper.kernels.attribution.spread_echo`);
    returns the echoes with none (readings with no echo count as such)."""
    width = hits.shape[1]
    lost = 0
    for i in range(cut.shape[0] - 1):
        m = cut[i + 1] - cut[i]
        if m == 0:
            lost += 1
            continue
        w = 1.0 / float(m) ** dilution
        for k in range(cut[i], cut[i + 1]):
            r = cells[k] // width
            hits[r, cells[k] - r * width] += w
    return lost
