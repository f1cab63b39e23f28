"""Feature correction with a scan's free-space scan (ALGORITHM.md §4, eqs. 9-10), compiled.

The compiled twin of :mod:`pipeline.mapper.correction` (read that module for the method and
its decisions: the exact 3σ touched test, particles drawn as ``μ + L z`` with all x-draws
then all y-draws of the scan's touched features from the mapper's ``Generator``, survivors
refit from their own positions or cell centres, the split guard, protection). The particle
normals are the same ``numpy.random.Generator``'s numbers in the same order (its PCG64 state
passed in as words and advanced by :mod:`.normals`, numpy's algorithms inlined), the
arithmetic is the reference's in its order,
and the sums over particles are numpy's pairwise summation (:func:`pairwise_sum`), so the
kernel and the reference agree bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from pipeline.mapper.kernels.ellipse import ellipse_row_span, ellipse_rows
from pipeline.mapper.kernels.features import (
    N_SLOTS,
    FeatureArrays,
    delete_feature,
    move_feature,
)
from pipeline.mapper.kernels.free_space import any_free, is_free
from pipeline.mapper.kernels.normals import fill_standard_normal

# As correction._SINGULAR: relative determinant below which a refit counts as singular.
SINGULAR = 1e-12
_TINY = np.finfo(np.float64).tiny

# Positions in the counters array the mapper kernels fill.
CREATED, MERGED, CORRECTED, DELETED, PROTECTED, SPLIT, CELLS_FREED = range(7)


@njit(cache=True)
def _pairwise_block(a: np.ndarray, lo: int, n: int) -> float:
    """numpy's pairwise sum of at most 128 values: 8 accumulators, then the rest in order."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    stop = n - n % 8
    while i < stop:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True)
def pairwise_sum(a: np.ndarray, lo: int, n: int) -> float:
    """``a[lo:lo+n]`` summed as numpy's ``add.reduce`` does along a contiguous axis, so the
    result equals ``np.sum`` bit for bit: blocks of up to 128 values (:func:`_pairwise_block`),
    longer runs split at ``n/2`` rounded down to a multiple of 8 and the halves added.

    The recursion is unrolled onto a small stack: numba's on-disk cache cannot load
    self-recursive functions (they crash the process).
    """
    if n <= 128:
        return _pairwise_block(a, lo, n)
    los = np.empty(64, dtype=np.int64)
    ns = np.empty(64, dtype=np.int64)
    stage = np.zeros(64, dtype=np.int64)
    vals = np.empty(65)
    top = 0
    nv = 0
    los[0] = lo
    ns[0] = n
    while top >= 0:
        start, m = los[top], ns[top]
        if m <= 128:
            vals[nv] = _pairwise_block(a, start, m)
            nv += 1
            top -= 1
            continue
        half = m // 2
        half -= half % 8
        if stage[top] == 0:  # the left half next
            stage[top] = 1
            top += 1
            los[top], ns[top], stage[top] = start, half, 0
        elif stage[top] == 1:  # then the right half
            stage[top] = 2
            top += 1
            los[top], ns[top], stage[top] = start + half, m - half, 0
        else:  # both done: left + right
            vals[nv - 2] = vals[nv - 2] + vals[nv - 1]
            nv -= 1
            top -= 1
    return vals[0]


@njit(cache=True)
def touched_slots(fa: FeatureArrays, row0: int, col0: int, col1: int, starts: np.ndarray,
                  c0s: np.ndarray, c1s: np.ndarray, gx: float, gy: float, res: float,
                  width: int, height: int) -> np.ndarray:
    """Slots of live features whose 3σ ellipse holds a free cell centre of the union
    (:mod:`.free_space`), ascending: their 3σ box meets the union's box, then some row span
    of the ellipse meets a free interval."""
    h = starts.shape[0] - 1
    w = col1 - col0 + 1
    x_lo = gx + (col0 + 0.5) * res
    x_hi = gx + ((col0 + w) - 0.5) * res
    y_lo = gy + (row0 + 0.5) * res
    y_hi = gy + ((row0 + h) - 0.5) * res
    n = fa.meta[N_SLOTS]
    out = np.empty(n, dtype=np.int64)
    m = 0
    box = fa.box
    for s in range(n):
        if not (box[s, 0] >= x_lo and box[s, 1] >= -x_hi and box[s, 2] >= y_lo
                and box[s, 3] >= -y_hi):
            continue
        mx, my = fa.mean[s, 0], fa.mean[s, 1]
        cxx, cxy, cyy = fa.cov[s, 0], fa.cov[s, 1], fa.cov[s, 2]
        r0, r1 = ellipse_rows(my, cyy, 3.0, gy, res, height)
        r0 = max(r0, row0)
        r1 = min(r1, row0 + h - 1)
        # Prefilter: a free cell in the ellipse's rows within its 3σ x-extent (one cell
        # wider: rounding never puts an ellipse cell outside). Most box candidates fail it.
        hx = 3.0 * math.sqrt(cxx)
        ca = int(np.ceil(((mx - hx) - gx) / res - 0.5)) - 1
        cb = int(np.floor(((mx + hx) - gx) / res - 0.5)) + 1
        near = False
        for row in range(r0, r1 + 1):
            if any_free(starts, c0s, c1s, row - row0, ca, cb):
                near = True
                break
        if not near:
            continue
        for row in range(r0, r1 + 1):
            a, b = ellipse_row_span(mx, my, cxx, cxy, cyy, 3.0, row, gx, gy, res, width)
            if any_free(starts, c0s, c1s, row - row0, a, b):
                out[m] = s
                m += 1
                break
    return out[:m]


@njit(cache=True)
def _free_at(row0: int, col0: int, col1: int, starts: np.ndarray, c0s: np.ndarray,
             c1s: np.ndarray, cx: float, cy: float) -> bool:
    """Whether the cell of window column cx − 1, row cy − 1 (integer-valued floats, the
    reference's window-relative + 1 coordinates) is free."""
    if cx >= 1.0 and cx <= col1 - col0 + 1 and cy >= 1.0 and cy <= starts.shape[0] - 1:
        return is_free(starts, c0s, c1s, int(cy) - 1, int(cx) - 1 + col0)
    return False


@njit(cache=True)
def correct_features(fa: FeatureArrays, row0: int, col0: int, col1: int, starts: np.ndarray,
                     c0s: np.ndarray, c1s: np.ndarray, gx: float, gy: float, res: float,
                     width: int, height: int, pcg: np.ndarray,
                     n_particles: int, keep_n: float, protect_times: int, floor2: float,
                     split_guard: bool, refit_cells: bool, counters: np.ndarray) -> None:
    """Apply §4 to every feature touched by the union; counts into ``counters``; the
    normals come from (and advance) ``pcg``, a PCG64 state (:func:`.normals.pcg64_words`)."""
    slots = touched_slots(fa, row0, col0, col1, starts, c0s, c1s, gx, gy, res, width, height)
    f = slots.shape[0]
    if f == 0:
        return
    npart = n_particles
    z = np.empty((2, f, npart))
    fill_standard_normal(pcg, z.reshape(-1))
    inv = 1.0 / res
    offx = float(col0 - 1)
    offy = float(row0 - 1)
    px = np.empty(npart)
    py = np.empty(npart)
    sv = np.empty(npart)
    buf = np.empty(npart)
    dxs = np.empty(npart)
    dys = np.empty(npart)
    for j in range(f):
        s = slots[j]
        mx, my = fa.mean[s, 0], fa.mean[s, 1]
        cxx0, cxy0, cyy0 = fa.cov[s, 0], fa.cov[s, 1], fa.cov[s, 2]
        l11 = math.sqrt(cxx0)
        l21 = cxy0 / l11 if l11 > 0 else 0.0
        l22 = math.sqrt(max(cyy0 - l21 * l21, 0.0))
        ax = (mx - gx) * inv - offx
        ay = (my - gy) * inv - offy
        sx = l11 * inv
        sy = l22 * inv
        cr = l21 * inv
        m = 0
        for i in range(npart):
            z0 = z[0, j, i]
            p = z0 * sx + ax
            q = (z[1, j, i] * sy + ay) + cr * z0
            cx = np.floor(p)
            cy = np.floor(q)
            alive = not _free_at(row0, col0, col1, starts, c0s, c1s, cx, cy)
            if refit_cells:
                p = cx + 0.5
                q = cy + 0.5
            px[i] = p
            py[i] = q
            sv[i] = 1.0 if alive else 0.0
            m += alive
        refit = m >= keep_n
        if refit:
            mr = float(m)
            for i in range(npart):
                buf[i] = px[i] * sv[i]
            g0 = (0.0 + pairwise_sum(buf, 0, npart)) / mr
            for i in range(npart):
                buf[i] = py[i] * sv[i]
            g1 = (0.0 + pairwise_sum(buf, 0, npart)) / mr
            for i in range(npart):
                dxs[i] = (px[i] - g0) * sv[i]
                dys[i] = (py[i] - g1) * sv[i]
            scale_c = res * res / max(mr - 1.0, 1.0)
            for i in range(npart):
                buf[i] = dxs[i] * dxs[i]
            cxx = (0.0 + pairwise_sum(buf, 0, npart)) * scale_c
            for i in range(npart):
                buf[i] = dys[i] * dys[i]
            cyy = (0.0 + pairwise_sum(buf, 0, npart)) * scale_c
            for i in range(npart):
                buf[i] = dxs[i] * dys[i]
            cxy = (0.0 + pairwise_sum(buf, 0, npart)) * scale_c
            tr = max(cxx + cyy, _TINY)
            det = cxx * cyy - cxy * cxy
            if mr < 3 or cxx <= 0 or cyy <= 0 or det <= SINGULAR * tr * tr:
                cxx = cxx + floor2
                cyy = cyy + floor2
            if split_guard and _free_at(row0, col0, col1, starts, c0s, c1s, np.floor(g0),
                                        np.floor(g1)):
                counters[SPLIT] += 1
                refit = False
            if refit:
                move_feature(fa, s, gx + (g0 + offx) * res, gy + (g1 + offy) * res, cxx, cxy,
                             cyy)
                counters[CORRECTED] += 1
        if not refit:
            if fa.measured[s] >= protect_times:
                fa.measured[s] -= 1
                counters[PROTECTED] += 1
            else:
                delete_feature(fa, s)
                counters[DELETED] += 1
