"""Compiled E-step of the detection model (ALGORITHM.md §11): one pass over the readings.

A reading's cone out to ``cones[i, 2]`` (the far edge of its echo's arc, or ``r_max`` for a
reading with no echo) is visited cell by cell (:mod:`pipeline.mapper.kernels.cone`; its row
spans computed for all its rows at once, :func:`~pipeline.mapper.kernels.cone.cone_row_spans`). Every
surface of the map (listed row by row) stops the rays that meet it: it either answers or reflects the
pulse away, so nothing behind it (within its angular width, bins uniform in the tangent of
the bearing off the axis, as :mod:`pipeline.mapper.kernels.specular`) is reached by this
reading. A reached surface is met at incidence θ against its normal ``(nx, ny)``; it falls
in incidence bin ``b`` (``bins`` equal bins over [0, 90°]) when its normal's consistency
``q ≥ ½``, else in the last bin (orientation unknown). Two tallies:

* per reading (``stats``, ``(2, bins + 1)``): *answered* (``stats[0, b] += 1``): of the
  reached surfaces on the echo's arc (``r_inner ≤ dist``), the one met closest to its
  normal produced the echo (bin ``b``; the others on the arc are neither answered nor
  passed); *passed* (``stats[1, b] += 1`` once for each bin ``b`` with one): a reached
  surface closer than ``r_free`` and short of the arc (or the reading has no echo);
* per reached surface cell of known orientation (``reaches``, ``(2, bins)``): on the echo's
  arc (``reaches[0, b] += 1``: it may have answered) or short of it, closer than
  ``r_free`` (``reaches[1, b] += 1``: it did not).

``stats[0] / (stats[0] + stats[1])`` is the share of readings that reached a surface at that
incidence and were answered by it; ``reaches[0] / reaches.sum(0)`` the chance that a
surface cell met at that incidence answers. Deterministic.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from pipeline.mapper.kernels.attribution import reach_cells, span_buffers
from pipeline.mapper.kernels.specular import MAX_BINS, listed_row_spans, shade, shadow_bins
from pipeline.mapper.types import F32, F64, I32, B


@njit(cache=True, inline="always")
def incidence_bin(dx: float, dy: float, dist: float, nx: float, ny: float, bins: int) -> int:
    """The incidence bin (``bins`` equal bins over [0, 90°]) of the ray ``(dx, dy)`` on a
    surface with unit normal ``(nx, ny)``."""
    c = min(abs(dx * nx + dy * ny) / max(dist, 1e-12), 1.0)
    return min(int(math.acos(c) / (0.5 * math.pi) * bins), bins - 1)


@njit(cache=True, nogil=True)
def detection_counts(
    cones: F64, up_down: B, r_inner: F64, r_free: F64, alpha: F64, half_fov: F64,
    gx: float, gy: float, res: float, occ_index: I32, occ_cols: I32, nx: F32, ny: F32,
    cons: F32, stats: F64, reaches: F64,
) -> None:
    """Add each reading's answered and passed surfaces to ``stats`` ``(2, bins + 1)`` and
    its reached surface cells of known orientation to ``reaches`` ``(2, bins)`` (module
    doc); the surfaces are listed row by row (``occ_index, occ_cols`` as
    :func:`~pipeline.mapper.kernels.specular.cell_lists`), so a span costs its surfaces,
    not its cells."""
    height, width = cons.shape
    bins = stats.shape[1] - 1
    rows, c0s, c1s = span_buffers(cones, res)
    size = reach_cells(cones, res) ** 2
    cell_r = np.empty(size, dtype=np.int64)  # the reading's surfaces ahead of the sonar
    cell_c = np.empty(size, dtype=np.int64)
    cell_d = np.empty(size, dtype=np.float64)
    cell_t = np.empty(size, dtype=np.float64)
    stop = np.empty(MAX_BINS, dtype=np.float64)
    passed = np.zeros(bins + 1, dtype=np.bool_)
    for i in range(cones.shape[0]):
        ox, oy, r_out = cones[i, 0], cones[i, 1], cones[i, 2]
        a, hb = alpha[i], half_fov[i]
        # edge_sector_spans' spans, on the rows that hold a surface in the cone's columns
        n = listed_row_spans(cones, up_down, i, a, hb, occ_index, gx, gy, res, height, width,
                             rows, c0s, c1s)
        ca, sa = math.cos(a), math.sin(a)
        t_edge = math.tan(hb)
        nb = shadow_bins(hb, r_out, res)
        bin_w = 2.0 * t_edge / nb
        stop[:nb] = np.inf
        # The surfaces stop the rays (their shadows); listed for the second sweep.
        m = 0
        for k in range(n):
            r = rows[k]
            dy = gy + (r + 0.5) * res - oy
            for j in range(occ_index[r, c0s[k]], occ_index[r, c1s[k] + 1]):
                c = occ_cols[j]
                dx = gx + (c + 0.5) * res - ox
                along = dx * ca + dy * sa
                if along <= 0.0:
                    continue
                dist = math.sqrt(dx * dx + dy * dy)
                t = (dy * ca - dx * sa) / along
                shade(stop, nb, dist, t, t_edge, res, bin_w)
                cell_r[m] = r
                cell_c[m] = c
                cell_d[m] = dist
                cell_t[m] = t
                m += 1
        # The reached ones count.
        passed[:] = False
        best = bins + 1  # the answering surface's bin (none yet)
        for j in range(m):
            dist, t = cell_d[j], cell_t[j]
            kb = math.floor((t + t_edge) / bin_w)
            if dist > stop[min(max(kb, 0), nb - 1)]:
                continue
            r, c = cell_r[j], cell_c[j]
            b = bins
            if cons[r, c] >= 0.5:
                dx = gx + (c + 0.5) * res - ox
                dy = gy + (r + 0.5) * res - oy
                b = incidence_bin(dx, dy, dist, nx[r, c], ny[r, c], bins)
            if dist >= r_inner[i]:
                best = min(best, b)
                if b < bins:
                    reaches[0, b] += 1.0
            elif dist < r_free[i]:
                passed[b] = True
                if b < bins:
                    reaches[1, b] += 1.0
        if best <= bins:
            stats[0, best] += 1.0
        for b in range(bins + 1):
            if passed[b]:
                stats[1, b] += 1.0
