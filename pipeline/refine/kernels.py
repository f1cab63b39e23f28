"""Pose refinement's inner loops compiled (numba, ``@njit(cache=True, nogil=True)``:
they release the GIL, so candidate calibrations score on parallel threads); the numpy
versions in :mod:`pipeline.refine.scores` stay as the reference the tests compare with.

Design notes and the measurements behind them: docs/research/pose_refinement.md, "kernels.py".
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

import pipeline.mapper.kernels  # noqa: F401  (chooses numba's cache directory first)
from formats.arrays import F64
from pipeline.mapper.kernels.cone import wrap_angle


def gaussian_weights(sd_cells: float, truncate: float = 3.0) -> F64:
    """scipy.ndimage's 1-D Gaussian weights for ``sd_cells`` (cells)."""
    radius = int(truncate * sd_cells + 0.5)
    x = np.arange(-radius, radius + 1)
    phi = np.exp(-0.5 / (sd_cells * sd_cells) * x**2)
    return np.asarray(phi / phi.sum())


def gaussian_blur(grid: F64, sd_cells: float) -> F64:
    """``scipy.ndimage.gaussian_filter(grid, sd_cells, mode="constant", truncate=3.0)``,
    bit for bit (:func:`blur_constant` with :func:`gaussian_weights`)."""
    return np.asarray(blur_constant(np.ascontiguousarray(grid, dtype=np.float64),
                                    gaussian_weights(sd_cells)))


@njit(cache=True, nogil=True)
def blur_constant(grid: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``grid`` filtered by the odd, symmetric 1-D ``weights`` along the rows, then along
    the columns, zeros outside (scipy.ndimage's ``mode="constant"``), each output summed as
    scipy's symmetric correlation sums it (the centre first, then the pairs from the
    outermost in): bit for bit. Each pass runs along whole rows, so the sums of neighbouring
    cells advance together (the compiler vectorises them; each cell's own order is kept)."""
    h, w = grid.shape
    rad = weights.shape[0] // 2
    padded = np.zeros((h + 2 * rad, w))
    padded[rad:rad + h] = grid
    rows = np.zeros((h, w + 2 * rad))  # the first pass, padded for the second
    for r in range(h):
        out = rows[r, rad:rad + w]
        centre = padded[r + rad]
        for c in range(w):
            out[c] = centre[c] * weights[rad]
        for j in range(rad, 0, -1):
            wj, above, below = weights[rad - j], padded[r + rad - j], padded[r + rad + j]
            for c in range(w):
                out[c] += (above[c] + below[c]) * wj
    blurred = np.empty((h, w))
    for r in range(h):
        line, out = rows[r], blurred[r]
        for c in range(w):
            out[c] = line[c + rad] * weights[rad]
        for j in range(rad, 0, -1):
            wj = weights[rad - j]
            for c in range(w):
                out[c] += (line[c + rad - j] + line[c + rad + j]) * wj
    return blurred


@njit(cache=True, nogil=True)
def gaussian_at(u: float, rad: int, sd: float, out: np.ndarray) -> int:
    """Gaussian weights (sd ``sd`` cells, normalised to sum 1) at the ``2 rad + 2`` cells
    ``c0 … c0 + 2 rad + 1`` around the continuous cell coordinate ``u`` (cell ``c``'s
    centre at ``c``), written to ``out``; returns ``c0``."""
    c0 = math.floor(u) - rad
    # exp(−d²/2sd²) at d = u − c0, then each next cell's from the last (d one less): times
    # exp((2d − 1)/2sd²), a factor itself times exp(−1/sd²) from cell to cell — two
    # exponentials per call instead of one per cell (they were most of the score's time)
    d, inv = u - c0, 1.0 / (sd * sd)
    if 0.5 * d * d * inv > 700.0:  # the first weight would underflow: one per cell
        for m in range(2 * rad + 2):
            e = u - (c0 + m)
            out[m] = math.exp(-0.5 * e * e * inv)
    else:
        g = math.exp(-0.5 * d * d * inv)
        ratio = math.exp((d - 0.5) * inv)
        fall = math.exp(-inv)
        for m in range(2 * rad + 2):
            out[m] = g
            g *= ratio
            ratio *= fall
    total = 0.0
    for m in range(2 * rad + 2):
        total += out[m]
    for m in range(2 * rad + 2):
        out[m] /= total
    return c0


@njit(cache=True, nogil=True)
def splat(grid: np.ndarray, u: float, v: float) -> None:
    """One unit at the continuous cell coordinates (column ``u``, row ``v``; cell centres
    at integers) shared bilinearly by the four cells around it (cloud in cell)."""
    r0, c0 = math.floor(v), math.floor(u)
    fr, fc = v - r0, u - c0
    grid[r0, c0] += (1.0 - fr) * (1.0 - fc)
    grid[r0, c0 + 1] += (1.0 - fr) * fc
    grid[r0 + 1, c0] += fr * (1.0 - fc)
    grid[r0 + 1, c0 + 1] += fr * fc


@njit(cache=True, nogil=True)
def blurred_pair(hits: np.ndarray, frees: np.ndarray, wu: np.ndarray, wv: np.ndarray,
                 r0: int, c0: int) -> tuple[float, float]:
    """``Σ_m wv[m] Σ_q wu[q] grid[r0 + m, c0 + q]`` of both grids (each row's sum over
    ``q`` in order, then the rows' in order). Two rows at a time: four independent sums
    in flight instead of two (the same sums in the same order, ~0.2 ms less of a 2.3 ms
    call on the drifted Örebro)."""
    k = wu.shape[0]  # even: 2 rad + 2
    hh = 0.0
    ff = 0.0
    for m in range(0, k, 2):
        h0, f0 = hits[r0 + m], frees[r0 + m]
        h1, f1 = hits[r0 + m + 1], frees[r0 + m + 1]
        sh0 = sf0 = sh1 = sf1 = 0.0
        for q in range(k):
            u = wu[q]
            sh0 += u * h0[c0 + q]
            sf0 += u * f0[c0 + q]
            sh1 += u * h1[c0 + q]
            sf1 += u * f1[c0 + q]
        hh += wv[m] * sh0
        ff += wv[m] * sf0
        hh += wv[m + 1] * sh1
        ff += wv[m + 1] * sf1
    return hh, ff


@njit(cache=True, nogil=True)
def consistency_score(wx: np.ndarray, wy: np.ndarray, ox: np.ndarray, oy: np.ndarray,
                      steps: np.ndarray, band: float, res: float, pad: float,
                      sd_cells: float, rad: int, min_evidence: float) -> float:
    """Mean over echoes of the best ``H / (H + F)`` on their arc (see the module docstring).

    ``wx, wy`` (echoes, arc points) the arc points in the world, ``ox, oy`` each echo's
    sonar, ``steps`` the distances sampled along each ray, free up to ``band`` short of the
    arc; cells of ``res``, the blur's sd ``sd_cells`` cells read over ``±rad`` cells. Hits
    and free samples are shared bilinearly by four cells and the blurred densities read at
    each arc point's own position, so the score moves with the echoes' poses inside a cell
    (a ray's free samples still start and stop at whole steps along it).
    """
    n, a = wx.shape
    if n == 0 or a == 0:
        return 0.0
    ns = steps.shape[0]
    # The box of the arc points and the sonars (the free samples lie between them).
    xmin, ymin, xmax, ymax = np.inf, np.inf, -np.inf, -np.inf
    for i in range(n):
        xmin, xmax = min(xmin, ox[i]), max(xmax, ox[i])
        ymin, ymax = min(ymin, oy[i]), max(ymax, oy[i])
        for j in range(a):
            xmin, xmax = min(xmin, wx[i, j]), max(xmax, wx[i, j])
            ymin, ymax = min(ymin, wy[i, j]), max(ymax, wy[i, j])
    margin = pad + (rad + 2) * res
    x0, y0 = xmin - margin, ymin - margin
    w = int((xmax + margin - x0) / res) + 2
    h = int((ymax + margin - y0) / res) + 2
    hits = np.zeros((h, w))
    frees = np.zeros((h, w))
    fu = np.empty(ns)  # a ray's free samples, in cell coordinates
    fv = np.empty(ns)
    for i in range(n):
        oxi, oyi = ox[i], oy[i]
        for j in range(a):
            px, py = wx[i, j], wy[i, j]
            splat(hits, (px - x0) / res - 0.5, (py - y0) / res - 0.5)
            dx, dy = px - oxi, py - oyi
            r = math.hypot(dx, dy)
            # the steps short of r − band (``steps`` increase): their positions in a loop
            # without a branch, which the compiler vectorises (its divisions were most of
            # the spreading's time), then spread one by one
            free = 0
            while free < ns and steps[free] < r - band:
                free += 1
            length = max(r, 1e-9)
            for s in range(free):
                frac = steps[s] / length
                fu[s] = (oxi + dx * frac - x0) / res - 0.5
                fv[s] = (oyi + dy * frac - y0) / res - 0.5
            for s in range(free):
                splat(frees, fu[s], fv[s])
    # The blurred densities at each arc point; an echo scores its best covered point.
    wu = np.empty(2 * rad + 2)
    wv = np.empty(2 * rad + 2)
    total = 0.0
    scored = 0
    for i in range(n):
        best = -1.0
        for j in range(a):
            c0 = gaussian_at((wx[i, j] - x0) / res - 0.5, rad, sd_cells, wu)
            r0 = gaussian_at((wy[i, j] - y0) / res - 0.5, rad, sd_cells, wv)
            hh, ff = blurred_pair(hits, frees, wu, wv, r0, c0)
            seen = hh + ff
            if seen >= min_evidence:
                ratio = hh / max(seen, 1e-12)
                if ratio > best:
                    best = ratio
        if best >= 0:
            total += best
            scored += 1
    return total / scored if scored > 0 else 0.0


@njit(cache=True, nogil=True)
def consistency_placed(px: np.ndarray, py: np.ndarray, cos: np.ndarray, sin: np.ndarray,
                       bx: np.ndarray, by: np.ndarray, sx: np.ndarray, sy: np.ndarray,
                       steps: np.ndarray, band: float, res: float, pad: float,
                       sd_cells: float, rad: int, min_evidence: float) -> float:
    """:func:`consistency_score` of the arcs ``(bx, by)`` (echoes × points) and sonars
    ``(sx, sy)``, each in its echo's robot frame, placed at the poses ``(px, py)`` whose
    yaws have ``cos``, ``sin`` (:func:`placed`)."""
    wx, wy = placed(px, py, cos, sin, bx, by)
    ox, oy = placed(px, py, cos, sin, sx.reshape(-1, 1), sy.reshape(-1, 1))
    return consistency_score(wx, wy, ox.ravel(), oy.ravel(), steps, band, res, pad, sd_cells,
                             rad, min_evidence)


@njit(cache=True, nogil=True)
def placed(px: np.ndarray, py: np.ndarray, cos: np.ndarray, sin: np.ndarray, bx: np.ndarray,
           by: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The points ``(bx, by)`` (echoes × points, each row in its echo's robot frame) at the
    poses ``(px, py)`` whose yaws have ``cos``, ``sin``: operation for operation as
    :func:`pipeline.se2.transform_points` places them, without its numpy temporaries."""
    n, a = bx.shape
    wx = np.empty((n, a))
    wy = np.empty((n, a))
    for i in range(n):
        for j in range(a):
            wx[i, j] = px[i] + cos[i] * bx[i, j] - sin[i] * by[i, j]
            wy[i, j] = py[i] + sin[i] * bx[i, j] + cos[i] * by[i, j]
    return wx, wy


DENSE_CELLS_PER_POINT = 16  # binned_sharpness: an array of bins up to this many per point


@njit(cache=True, nogil=True)
def binned_sharpness(x: np.ndarray, y: np.ndarray, size: float) -> float:
    """``Σ n² / (Σ n)²`` of the points' counts ``n`` in square bins of ``size``, averaged
    over two grids offset by half a bin (``scores.BinnedSharpness``). The bins are counted
    in an array over the points' box where it has at most :data:`DENSE_CELLS_PER_POINT`
    bins per point (a calibrated track: 4× faster than hashing, measured on the Intel
    lab's wide scan), else in a hash table (a wrong bias can spread the points far)."""
    n = x.shape[0]
    if n == 0:
        return 0.0
    qx = np.empty(n)
    qy = np.empty(n)
    for i in range(n):
        qx[i] = x[i] / size
        qy[i] = y[i] / size
    total = 0.0
    for shift in (0.0, 0.5):
        c_lo = c_hi = math.floor(qx[0] + shift)
        r_lo = r_hi = math.floor(qy[0] + shift)
        for i in range(n):
            c, r = math.floor(qx[i] + shift), math.floor(qy[i] + shift)
            c_lo, c_hi, r_lo, r_hi = min(c_lo, c), max(c_hi, c), min(r_lo, r), max(r_hi, r)
        w, h = c_hi - c_lo + 1, r_hi - r_lo + 1
        if w * h <= DENSE_CELLS_PER_POINT * n:
            sumsq = _dense_sumsq(qx, qy, shift, c_lo, r_lo, w, h)
        else:
            sumsq = _hashed_sumsq(qx, qy, shift)
        total += float(sumsq) / float(n) ** 2
    return total / 2


@njit(cache=True, nogil=True)
def _dense_sumsq(qx: np.ndarray, qy: np.ndarray, shift: float, c_lo: int, r_lo: int, w: int,
                 h: int) -> int:
    """``Σ n²`` of the counts per bin (bin coordinates ``floor(q + shift)``), in an array of
    the ``w × h`` bins from ``(c_lo, r_lo)``."""
    counts = np.zeros(w * h, dtype=np.int64)
    sumsq = 0
    for i in range(qx.shape[0]):
        k = (math.floor(qy[i] + shift) - r_lo) * w + (math.floor(qx[i] + shift) - c_lo)
        sumsq += 2 * counts[k] + 1  # (c + 1)² − c²
        counts[k] += 1
    return sumsq


@njit(cache=True, nogil=True)
def _hashed_sumsq(qx: np.ndarray, qy: np.ndarray, shift: float) -> int:
    """:func:`_dense_sumsq` with the bins in a hash table (multiplicative hashing, the
    product's high bits; linear probing)."""
    n = qx.shape[0]
    bits = 1
    while (1 << bits) < 2 * n:
        bits += 1
    slots = 1 << bits
    keys = np.empty(slots, dtype=np.int64)
    counts = np.zeros(slots, dtype=np.int64)
    sumsq = 0
    for i in range(n):
        key = math.floor(qx[i] + shift) * (1 << 32) + math.floor(qy[i] + shift)
        h = ((key * 0x5851F42D4C957F2D) >> (64 - bits)) & (slots - 1)
        while counts[h] != 0 and keys[h] != key:
            h = (h + 1) & (slots - 1)
        keys[h] = key
        sumsq += 2 * counts[h] + 1
        counts[h] += 1
    return sumsq


@njit(cache=True, nogil=True)
def binned_sharpness_placed(px: np.ndarray, py: np.ndarray, cos: np.ndarray, sin: np.ndarray,
                            bx: np.ndarray, by: np.ndarray, size: float) -> float:
    """:func:`binned_sharpness` of the points ``(bx, by)`` (echoes × points, each row in its
    echo's robot frame) placed at the poses ``(px, py)`` whose yaws have ``cos``, ``sin``
    (:func:`placed`; the wide scan places 2,000 echoes' arcs per candidate)."""
    x, y = placed(px, py, cos, sin, bx, by)
    return binned_sharpness(x.ravel(), y.ravel(), size)


SEGMENT_M = 1.0  # poses_at: the steps summed per segment of this much travel
TAYLOR_TERMS = 7  # ... each segment's turn under a bias expanded to this many terms
MAX_TURN = 0.05  # ... valid while the bias turns a segment's steps by at most this (rad):
# the first term left out is MAX_TURN⁷ / 7! ≈ 2e-13 of the segment's length


@njit(cache=True, nogil=True)
def step_segments(yaw0: float, lx: np.ndarray, ly: np.ndarray, dyaw: np.ndarray,
                  ds: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                           np.ndarray, np.ndarray, np.ndarray,
                                                           np.ndarray, np.ndarray, np.ndarray]:
    """What :func:`poses_at` needs of the steps, once per trajectory: each pose's travel
    ``S`` before it and each step's world translation ``w = e^{iΦ}(lx + i·ly)`` (``Φ``: the
    heading with no bias, unwrapped); the steps cut into segments at the pose indices of
    ``at`` and every :data:`SEGMENT_M` of travel (``bounds``, pose indices; none where the
    robot has not moved since the last); per segment its travel's centre ``S_c``,
    half-width and Taylor moments ``Σ w·(S − S_c)^k / k!``; and per ``at`` its bound, ``Φ``
    and ``S``."""
    n = lx.shape[0]
    phi, s = np.empty(n + 1), np.empty(n + 1)
    phi[0], s[0] = yaw0 + 0.0, 0.0
    for i in range(n):
        phi[i + 1] = phi[i] + dyaw[i]
        s[i + 1] = s[i] + ds[i]
    w = np.empty(n, np.complex128)
    for i in range(n):
        w[i] = complex(math.cos(phi[i]), math.sin(phi[i])) * complex(lx[i], ly[i])
    wanted = np.zeros(n + 1, np.bool_)
    for e in range(at.shape[0]):
        wanted[at[e]] = True
    cut = np.zeros(n + 1, np.bool_)
    cut[0] = True
    last = 0  # the last bound; a pose with no travel since shares it
    bound_of = np.zeros(n + 1, np.int64)
    for i in range(1, n + 1):
        if (i == n or wanted[i] or s[i] - s[last] >= SEGMENT_M) and s[i] != s[last]:
            cut[i], last = True, i
        bound_of[i] = last
    bounds = np.flatnonzero(cut)
    m = bounds.shape[0] - 1
    centre, half = np.zeros(m), np.zeros(m)
    moments = np.zeros((m, TAYLOR_TERMS), np.complex128)
    for g in range(m):
        lo, hi = bounds[g], bounds[g + 1]
        centre[g] = 0.5 * (s[lo] + s[hi - 1])
        half[g] = 0.5 * (s[hi - 1] - s[lo])
        for i in range(lo, hi):
            d, term = s[i] - centre[g], w[i]
            for k in range(TAYLOR_TERMS):
                moments[g, k] += term
                term = term * d / (k + 1)
    where = np.searchsorted(bounds, bound_of[at])
    return s, w, bounds, centre, half, moments, where, phi[at], s[at]


@njit(cache=True, nogil=True)
def poses_at(x0: float, y0: float, s: np.ndarray, w: np.ndarray, bounds: np.ndarray,
             centre: np.ndarray, half: np.ndarray, moments: np.ndarray, where: np.ndarray,
             phi_at: np.ndarray, s_at: np.ndarray, scale: np.ndarray,
             bias: np.ndarray) -> np.ndarray:
    """(calibrations, len(at), 3): the poses (x, y, heading wrapped to [−π, π) as numpy's
    ``np.mod`` wraps it) at the pose indices ``at`` of :func:`step_segments` composed from
    the first pose with each step's length times ``scale[j]`` and ``bias[j]`` per metre of
    travel added to its rotation — :meth:`pipeline.drift.Steps.drifted_many`'s poses to
    ~1e-11 m. The heading before step
    ``i`` is ``Φ_i + b·S_i``, so the position is ``x0 + scale·Σ_{i<p} w_i·e^{ib·S_i}``: per
    segment ``e^{ib·S_c}·Σ_k (ib)^k·moment_k`` (a cosine and a sine per segment, not per
    step; the steps one by one where the bias turns a segment's by more than
    :data:`MAX_TURN`), summed once per distinct bias and scaled per calibration (the scale
    multiplies every step alike)."""
    m, n_seg = scale.shape[0], centre.shape[0]
    out = np.empty((m, where.shape[0], 3))
    widest = half.max() if n_seg > 0 else 0.0
    total = np.empty(n_seg + 1, np.complex128)  # Σ w e^{ibS} up to each bound
    previous = math.nan
    for j in np.argsort(bias, kind="mergesort"):
        b = bias[j]
        if b != previous:
            previous = b
            total[0] = 0.0
            if abs(b) * widest <= MAX_TURN:
                ib = complex(0.0, b)
                for g in range(n_seg):
                    part = moments[g, TAYLOR_TERMS - 1]
                    for k in range(TAYLOR_TERMS - 2, -1, -1):
                        part = part * ib + moments[g, k]
                    turn = b * centre[g]
                    total[g + 1] = total[g] + complex(math.cos(turn), math.sin(turn)) * part
            else:
                for g in range(n_seg):
                    acc = total[g]
                    for i in range(bounds[g], bounds[g + 1]):
                        turn = b * s[i]
                        acc += w[i] * complex(math.cos(turn), math.sin(turn))
                    total[g + 1] = acc
        sc = scale[j]
        for e in range(where.shape[0]):
            p = total[where[e]]
            out[j, e, 0] = x0 + sc * p.real
            out[j, e, 1] = y0 + sc * p.imag
            out[j, e, 2] = wrap_angle(phi_at[e] + b * s_at[e])
    return out


@njit(cache=True, nogil=True)
def _reflect(i: int, n: int) -> int:
    """scipy.ndimage's ``mode="reflect"`` index (``d c b a | a b c d | d c b a``)."""
    period = 2 * n
    i %= period
    return i if i < n else period - 1 - i


@njit(cache=True, nogil=True)
def structure_tensor_at(gx: np.ndarray, gy: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                        weights: np.ndarray) -> np.ndarray:
    """(len(rows), 3): the structure tensor ``(sxx, syy, sxy)`` at the cells
    ``(rows[i], cols[i])`` of the gradient ``(gx, gy)`` (``numpy.gradient``'s, ``x`` along
    columns) — its outer products each filtered by ``scipy.ndimage.gaussian_filter`` with
    the 1-D ``weights`` (odd, symmetric; ``mode="reflect"``), read at those cells only: the rows pass, then the columns pass,
    each summed as scipy's symmetric correlation sums (centre first, then the pairs from
    the outermost in), so the values are the whole-grid filter's bit for bit."""
    h, w = gx.shape
    rad = weights.shape[0] // 2
    n = rows.shape[0]
    out = np.empty((n, 3))
    t1 = np.empty((2 * rad + 1, 3))  # the rows pass at the columns the columns pass reads
    for i in range(n):
        r, c = rows[i], cols[i]
        rr = _reflect(r, h)
        for v in range(-rad, rad + 1):
            cc = _reflect(c + v, w)
            gr, gc = gy[rr, cc], gx[rr, cc]
            a0, a1, a2 = gc * gc * weights[rad], gr * gr * weights[rad], gc * gr * weights[rad]
            for j in range(rad, 0, -1):
                r1, r2 = _reflect(r - j, h), _reflect(r + j, h)
                gr1, gc1 = gy[r1, cc], gx[r1, cc]
                gr2, gc2 = gy[r2, cc], gx[r2, cc]
                wj = weights[rad - j]
                a0 += (gc1 * gc1 + gc2 * gc2) * wj
                a1 += (gr1 * gr1 + gr2 * gr2) * wj
                a2 += (gc1 * gr1 + gc2 * gr2) * wj
            t1[v + rad, 0], t1[v + rad, 1], t1[v + rad, 2] = a0, a1, a2
        for k in range(3):
            s = t1[rad, k] * weights[rad]
            for j in range(rad, 0, -1):
                s += (t1[rad - j, k] + t1[rad + j, k]) * weights[rad - j]
            out[i, k] = s
    return out


@njit(cache=True, nogil=True)
def free_samples(ox: np.ndarray, oy: np.ndarray, rx: np.ndarray, ry: np.ndarray,
                 range_m: np.ndarray, steps: np.ndarray, band: float, x0: float, y0: float,
                 cell: float, counts: np.ndarray) -> tuple[float, float, float, float]:
    """The free-cone samples: echo ``i``'s rays from its sonar ``(ox, oy)`` to the points
    ``(rx, ry)[i]``, sampled at ``steps`` (fractions ``steps / range_m[i]`` of the way)
    short of ``range_m[i] − band`` and placed as ``o + (r − o)·frac`` (numpy's arithmetic),
    without the samples' arrays. Counts them into the cells of ``counts`` (origin
    ``(x0, y0)``, clipped into the grid; a grid of no cells counts nothing) and returns
    their box (x min, y min, x max, y max; ``inf, inf, -inf, -inf`` when there is none)."""
    h, w = counts.shape
    xmin, ymin, xmax, ymax = np.inf, np.inf, -np.inf, -np.inf
    for i in range(rx.shape[0]):
        for s in range(steps.shape[0]):
            if not steps[s] < range_m[i] - band:
                break
            frac = steps[s] / range_m[i]
            for j in range(rx.shape[1]):
                fx = ox[i] + (rx[i, j] - ox[i]) * frac
                fy = oy[i] + (ry[i, j] - oy[i]) * frac
                xmin, xmax = min(xmin, fx), max(xmax, fx)
                ymin, ymax = min(ymin, fy), max(ymax, fy)
                if h > 0 and w > 0:
                    r = min(max(int((fy - y0) / cell), 0), h - 1)
                    c = min(max(int((fx - x0) / cell), 0), w - 1)
                    counts[r, c] += 1.0
    return xmin, ymin, xmax, ymax


@njit(cache=True, nogil=True)
def correlation_grid(table: np.ndarray, h: int, w: int, fx: np.ndarray, fy: np.ndarray,
                     n_arc: int, centre: np.ndarray, origin_x: float, origin_y: float,
                     res: float, dyaw: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """The correlative match's log-likelihood over poses ``centre + (cells[a]·res,
    cells[b]·res, dyaw[k])`` (:func:`pipeline.refine.correlative._loglik`, whose numpy
    version it replaces bit for bit): ``table`` the per-cell log values (row-major ``h × w``,
    then one more: the value outside), ``fx, fy`` the query's arc points (echo-major,
    ``n_arc`` per echo); each echo scores its best arc point, summed over echoes in order.

    The table is padded by ``2P + 1`` cells of the outside value (``P`` the largest offset)
    and each point's cell clamped to ``P + 1`` outside the field, which moves no lookup
    from outside to inside: the inner loop runs without bounds tests, along a row."""
    n_cells = cells.shape[0]
    n_pts = fx.shape[0]
    n_echo = n_pts // n_arc
    reach = 0
    for a in range(n_cells):
        reach = max(reach, abs(cells[a]))
    pad = 2 * reach + 1
    wp = w + 2 * pad
    padded = np.full((h + 2 * pad) * wp, table[h * w])
    for r in range(h):
        padded[(r + pad) * wp + pad:(r + pad) * wp + pad + w] = table[r * w:(r + 1) * w]
    out = np.zeros((dyaw.shape[0], n_cells, n_cells))
    base = np.empty(n_pts, np.int64)
    best = np.empty((n_cells, n_cells))  # [b, a]: y offset, then x along a row
    for k in range(dyaw.shape[0]):
        th = centre[2] + dyaw[k]
        c, s = math.cos(th), math.sin(th)
        for p in range(n_pts):
            ix = math.floor((centre[0] + c * fx[p] - s * fy[p] - origin_x) / res)
            iy = math.floor((centre[1] + s * fx[p] + c * fy[p] - origin_y) / res)
            ix = min(max(ix, -reach - 1), w + reach)
            iy = min(max(iy, -reach - 1), h + reach)
            base[p] = (iy + pad) * wp + ix + pad
        for e in range(n_echo):
            best[:, :] = -np.inf
            for q in range(e * n_arc, (e + 1) * n_arc):
                if q > e * n_arc and base[q] == base[q - 1]:
                    continue  # the arc's previous point's cell: the same values
                for b in range(n_cells):
                    row = base[q] + cells[b] * wp
                    for a in range(n_cells):
                        best[b, a] = max(best[b, a], padded[row + cells[a]])
            for a in range(n_cells):
                for b in range(n_cells):
                    out[k, a, b] += best[b, a]
    return out


@njit(cache=True, nogil=True)
def beam_coverage(rx: np.ndarray, ry: np.ndarray, sx: np.ndarray, sy: np.ndarray,
                  length: np.ndarray, u: np.ndarray, beyond: float, origin_x: float,
                  origin_y: float, res: float, h: int, w: int) -> np.ndarray:
    """Cells (``h × w``, row-major from ``origin``) a ray crosses: from each echo's sensor
    ``(sx[e], sy[e])`` towards each of its arc points ``(rx[e, p], ry[e, p])`` (``length``
    their distance) and ``beyond`` m past it, sampled at the fractions ``u`` of that reach
    (:func:`pipeline.refine.correlative._coverage`, whose numpy version it replaces bit for
    bit: the same operations in the same order)."""
    cover = np.zeros((h, w), np.bool_)
    for e in range(rx.shape[0]):
        for p in range(rx.shape[1]):
            dx = rx[e, p] - sx[e]
            dy = ry[e, p] - sy[e]
            ratio = (length[e, p] + beyond) / max(length[e, p], 1e-9)
            for q in range(u.shape[0]):
                scale = ratio * u[q]
                ix = np.int64(math.floor((sx[e] + dx * scale - origin_x) / res))
                iy = np.int64(math.floor((sy[e] + dy * scale - origin_y) / res))
                if 0 <= ix < w and 0 <= iy < h:
                    cover[iy, ix] = True
    return cover


@njit(cache=True, nogil=True)
def normal_equations(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray,
                     w: np.ndarray, f: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(JᵀJ, Jᵀf)`` of ``J = diag(w)·M``, ``M`` the CSR matrix ``(data, indices, indptr)``
    with ``n`` columns (:mod:`pipeline.refine.trust_region`): ``JᵀJ`` dense, summed row by
    row (a pose graph's rows hold a few entries each)."""
    a = np.zeros((n, n))
    g = np.zeros(n)
    for r in range(indptr.shape[0] - 1):
        wr = w[r]
        for p in range(indptr[r], indptr[r + 1]):
            vp = wr * data[p]
            cp = indices[p]
            g[cp] += vp * f[r]
            for q in range(indptr[r], indptr[r + 1]):
                a[cp, indices[q]] += vp * (wr * data[q])
    return a, g
