"""Compiled per-reading loops of the specular method (ALGORITHM.md §10): echo attribution
with the map's surfaces in the way.

One reading's cone out to ``r_out`` (the far edge of its echo's arc) is visited cell by
cell. A cell the current map holds occupied, with surface normal line at angle ``psi``,
is *seen* by the reading's ray to it with probability ``visible(θ)`` (θ the incidence,
between the ray and the normal line; :func:`visible`); where that is below one half the
wall is silent to the ray and reflects it away, so the ray stops there: cells farther along
the same bearing (within the wall cell's angular width) get no free evidence and cannot
have produced the echo. Free evidence of an unoccluded cell closer than ``r_free`` is 1,
or ``visible(θ)`` for an occupied cell (an oblique wall passed by a ray says nothing about
the wall). Arc cells (``r_inner ≤ dist < r_out``) that are not occluded are counted
(``count`` mode) or, in ``attribute`` mode, are candidates unless the log's free evidence
rules them out (``free > ratio·arcs``, as §9); the echo is spread over its ``n``
candidates, ``1/n**dilution`` each, and each candidate also adds the echo's weighted
bearing as a doubled angle (``cos 2φ, sin 2φ``: an axial direction) to ``dir_c, dir_s``,
from which the next map takes its surface normals.

Loops run in reading order and add in that order, so results are deterministic.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from pipeline.mapper.kernels.cone import edge_sector_spans, max_sector_spans, wrap_angle
from pipeline.mapper.types import F32, F64, I32, B

MAX_BINS = 2048  # angular bins of one cone's occlusion profile


@njit(cache=True)
def visible(bearing: float, psi: float, table: F64, step: float) -> float:
    """The probability that a surface with normal line ``psi`` echoes a ray at
    ``bearing`` (rad): the critical-angle survival ``table`` at the incidence θ ∈ [0, π/2],
    sampled every ``step`` rad."""
    theta = abs(wrap_angle(bearing - psi))
    if theta > 0.5 * math.pi:
        theta = math.pi - theta
    k = int(theta / step)
    if k >= table.shape[0] - 1:
        return table[table.shape[0] - 1]
    f = theta / step - k
    return table[k] * (1.0 - f) + table[k + 1] * f


@njit(cache=True)
def _reach_cells(cones: F64, res: float) -> int:
    reach = 0.0
    for i in range(cones.shape[0]):
        reach = max(reach, cones[i, 2])
    return 2 * math.ceil(reach / res) + 3


@njit(cache=True)
def trace_readings(
    cones: F64, up_down: B, r_inner: F64, r_free: F64, alpha: F64, half_fov: F64,
    gx: float, gy: float, res: float, occ: B, occ_rows: I32, psi: F32, cons: F32,
    table: F64, step: float, attribute: bool, arc_c: F32, arc_s: F32, unknown_vis: float, free_in: F32, arcs_in: F32, ratio: float,
    dilution: float, free_out: F32, arcs_out: F32, hits: F32, dir_c: F32, dir_s: F32,
) -> int:
    """One pass over the readings ``cones`` (module doc); returns, in ``attribute`` mode,
    the echoes with no candidate cell."""
    height, width = free_out.shape
    reach = _reach_cells(cones, res)
    size = max_sector_spans(reach * res, res)
    rows = np.empty(size, dtype=np.int64)
    c0s = np.empty(size, dtype=np.int64)
    c1s = np.empty(size, dtype=np.int64)
    cand_r = np.empty(reach * reach, dtype=np.int64)
    cand_c = np.empty(reach * reach, dtype=np.int64)
    cand_b = np.empty(reach * reach, dtype=np.float64)
    stop = np.empty(MAX_BINS, dtype=np.float64)
    lost = 0
    for i in range(cones.shape[0]):
        ox, oy, r_out = cones[i, 0], cones[i, 1], cones[i, 2]
        a, hb = alpha[i], half_fov[i]
        n = edge_sector_spans(ox, oy, cones[i, 3], cones[i, 4], cones[i, 5], cones[i, 6],
                              up_down[i, 0], up_down[i, 1], 0.0, r_out, gx, gy, res, width,
                              height, rows, c0s, c1s)
        nb = min(MAX_BINS, int(math.ceil(2.0 * hb * r_out / res)) + 1)
        bin_w = 2.0 * hb / nb
        stopped = False
        for k in range(n):  # the oblique walls in the cone and their shadows
            r = rows[k]
            if occ_rows[r, c1s[k] + 1] == occ_rows[r, c0s[k]]:
                continue
            for c in range(c0s[k], c1s[k] + 1):
                if not occ[r, c]:
                    continue
                dx = gx + (c + 0.5) * res - ox
                dy = gy + (r + 0.5) * res - oy
                dist = math.hypot(dx, dy)
                bearing = math.atan2(dy, dx)
                if visible(bearing, psi[r, c], table, step) >= 0.5:
                    continue
                if not stopped:
                    stop[:nb] = np.inf
                    stopped = True
                rel = wrap_angle(bearing - a) + hb
                hw = 0.5 * res / max(dist, res)
                k0 = max(0, int(math.floor((rel - hw) / bin_w)))
                k1 = min(nb - 1, int(math.floor((rel + hw) / bin_w)))
                for kb in range(k0, k1 + 1):
                    if dist < stop[kb]:
                        stop[kb] = dist
        m = 0
        rf, ri = r_free[i], r_inner[i]
        for k in range(n):
            r = rows[k]
            for c in range(c0s[k], c1s[k] + 1):
                dx = gx + (c + 0.5) * res - ox
                dy = gy + (r + 0.5) * res - oy
                dist = math.hypot(dx, dy)
                bearing = math.atan2(dy, dx)
                if stopped:
                    kb = int(math.floor((wrap_angle(bearing - a) + hb) / bin_w))
                    kb = min(max(kb, 0), nb - 1)
                    if dist > stop[kb]:
                        continue
                if dist < rf and not attribute:
                    q = cons[r, c]
                    w = q * visible(bearing, psi[r, c], table, step) + (1.0 - q) * unknown_vis
                    free_out[r, c] += w
                if dist >= ri:
                    if attribute:
                        arc_c[r, c] += math.cos(2.0 * bearing)
                        arc_s[r, c] += math.sin(2.0 * bearing)
                    if not attribute:
                        arcs_out[r, c] += 1.0
                    elif free_in[r, c] <= ratio * arcs_in[r, c]:
                        cand_r[m] = r
                        cand_c[m] = c
                        cand_b[m] = bearing
                        m += 1
        if not attribute:
            continue
        if m == 0:
            lost += 1
            continue
        w = 1.0 / float(m) ** dilution
        for k in range(m):
            hits[cand_r[k], cand_c[k]] += w
            dir_c[cand_r[k], cand_c[k]] += w * math.cos(2.0 * cand_b[k])
            dir_s[cand_r[k], cand_c[k]] += w * math.sin(2.0 * cand_b[k])
    return lost
