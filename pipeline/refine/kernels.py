"""Pose refinement's inner loops compiled (numba, ``@njit(cache=True, nogil=True)``:
they release the GIL, so candidate calibrations score on parallel threads); the numpy
versions in :mod:`pipeline.refine.calibration` stay as the reference the tests compare with.

* :func:`consistency_score` — the echo consistency (``_Consistency``). The numpy version
  builds every free-cone sample as an array (echoes × arc points × steps along each ray),
  bins hits and free samples into two grids, blurs both whole grids with
  ``scipy.ndimage.gaussian_filter`` and reads them back at the arc points: 15-50 ms per
  candidate calibration on the drifted logs, ~150 candidates per scale search. The kernel
  does the same in two passes without the sample arrays, and blurs only where the score
  reads — at each arc point's cell, the separable Gaussian (scipy's weights: ``truncate =
  3``, normalised) summed over the raw counts around it (the box is padded by 4σ, so the
  reference's zero boundary is never reached). Same cells, same weights, sums in another
  order: scores agree with the reference to ~1e-14.
* :func:`binned_sharpness` — the wide heading-bias scan's score (``_BinnedSharpness``):
  points counted per bin in a hash table instead of sorted by ``numpy.unique``; the counts
  are integers, so the score is the reference's bit for bit.
* :func:`poses_at` — the odometry re-integrated under many calibrations, read at the
  echoes' poses (``_Placed.poses_many``): :meth:`pipeline.drift.Steps.drifted_many`'s
  arithmetic in the same order, one step at a time, without its (calibrations × poses)
  arrays — bit for bit (a wide scan integrates the Intel lab's 13,000 poses under 401
  biases; numpy's passes over those arrays were half of the scan's time).
* :func:`structure_tensor_at`, :func:`free_samples` — the surface
  association's (:meth:`pipeline.refine.surfaces.SurfaceScale._associate`): the structure
  tensor filtered at the hits' cells only instead of three whole-grid filters (of numpy's
  gradient, scipy's symmetric sums in their order: bit for bit), and the free cones
  counted per cell without their samples' arrays (numpy's arithmetic per sample: the same
  counts). Measured, an association 45 → 9 ms on the drifted Örebro (1,523 echoes),
  23 → 15 ms on the drifted Intel lab (6,484; benchmarks/RESULTS.md, twelfth session).

All are deterministic (no parallel reductions).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

import pipeline.mapper.kernels  # noqa: F401  (chooses numba's cache directory first)
from formats.arrays import F64


def gaussian_weights(sd_cells: float, truncate: float = 3.0) -> F64:
    """scipy.ndimage's 1-D Gaussian weights for ``sd_cells`` (cells)."""
    radius = int(truncate * sd_cells + 0.5)
    x = np.arange(-radius, radius + 1)
    phi = np.exp(-0.5 / (sd_cells * sd_cells) * x**2)
    return np.asarray(phi / phi.sum())


@njit(cache=True, nogil=True)
def consistency_score(wx: np.ndarray, wy: np.ndarray, ox: np.ndarray, oy: np.ndarray,
                      steps: np.ndarray, band: float, res: float, pad: float,
                      weights: np.ndarray, min_evidence: float) -> float:
    """Mean over echoes of the best ``H / (H + F)`` on their arc (see the module docstring).

    ``wx, wy`` (echoes, arc points) the arc points in the world, ``ox, oy`` each echo's
    sonar, ``steps`` the distances sampled along each ray, free up to ``band`` short of the
    arc, ``weights`` the blur's 1-D weights.
    """
    n, a = wx.shape
    if n == 0 or a == 0:
        return 0.0
    ns = steps.shape[0]
    # Pass 1: the box of the arc points and the free samples (as the reference computes it).
    xmin, ymin, xmax, ymax = np.inf, np.inf, -np.inf, -np.inf
    fxmin, fymin, fxmax, fymax = np.inf, np.inf, -np.inf, -np.inf
    for i in range(n):
        for j in range(a):
            px, py = wx[i, j], wy[i, j]
            xmin, xmax = min(xmin, px), max(xmax, px)
            ymin, ymax = min(ymin, py), max(ymax, py)
            dx, dy = px - ox[i], py - oy[i]
            r = math.hypot(dx, dy)
            for s in range(ns):
                along = steps[s]
                if not along < r - band:
                    break
                frac = along / max(r, 1e-9)
                fx, fy = ox[i] + dx * frac, oy[i] + dy * frac
                fxmin, fxmax = min(fxmin, fx), max(fxmax, fx)
                fymin, fymax = min(fymin, fy), max(fymax, fy)
    x0 = min(xmin, fxmin) - pad
    y0 = min(ymin, fymin) - pad
    w = int((max(xmax, fxmax) + pad - x0) / res) + 2
    h = int((max(ymax, fymax) + pad - y0) / res) + 2
    # Pass 2: raw counts of hits and free samples.
    hits = np.zeros((h, w))
    frees = np.zeros((h, w))
    cy = np.empty((n, a), dtype=np.int64)
    cx = np.empty((n, a), dtype=np.int64)
    for i in range(n):
        for j in range(a):
            px, py = wx[i, j], wy[i, j]
            cy[i, j] = int((py - y0) / res)
            cx[i, j] = int((px - x0) / res)
            hits[cy[i, j], cx[i, j]] += 1.0
            dx, dy = px - ox[i], py - oy[i]
            r = math.hypot(dx, dy)
            for s in range(ns):
                along = steps[s]
                if not along < r - band:
                    break
                frac = along / max(r, 1e-9)
                frees[int((oy[i] + dy * frac - y0) / res), int((ox[i] + dx * frac - x0) / res)] += 1.0
    # The blurred densities at each arc point's cell; an echo scores its best covered point.
    rad = weights.shape[0] // 2
    total = 0.0
    scored = 0
    for i in range(n):
        best = -1.0
        for j in range(a):
            hh = 0.0
            ff = 0.0
            for u in range(-rad, rad + 1):
                row = cy[i, j] + u
                if row < 0 or row >= h:
                    continue
                wu = weights[u + rad]
                sh = 0.0
                sf = 0.0
                for v in range(-rad, rad + 1):
                    col = cx[i, j] + v
                    if col < 0 or col >= w:
                        continue
                    sh += weights[v + rad] * hits[row, col]
                    sf += weights[v + rad] * frees[row, col]
                hh += wu * sh
                ff += wu * sf
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
def binned_sharpness(x: np.ndarray, y: np.ndarray, size: float) -> float:
    """``Σ n² / (Σ n)²`` of the points' counts ``n`` in square bins of ``size``, averaged
    over two grids offset by half a bin (``_BinnedSharpness``)."""
    n = x.shape[0]
    if n == 0:
        return 0.0
    bits = 1
    while (1 << bits) < 2 * n:
        bits += 1
    slots = 1 << bits
    keys = np.empty(slots, dtype=np.int64)
    counts = np.zeros(slots, dtype=np.int64)
    total = 0.0
    for shift in (0.0, 0.5):
        counts[:] = 0
        sumsq = 0
        for i in range(n):
            key = math.floor(x[i] / size + shift) * (1 << 32) + math.floor(y[i] / size + shift)
            # multiplicative hashing (the product's high bits), linear probing
            h = ((key * 0x5851F42D4C957F2D) >> (64 - bits)) & (slots - 1)
            while counts[h] != 0 and keys[h] != key:
                h = (h + 1) & (slots - 1)
            keys[h] = key
            sumsq += 2 * counts[h] + 1  # (c + 1)² − c²
            counts[h] += 1
        total += float(sumsq) / float(n) ** 2
    return total / 2


@njit(cache=True, nogil=True)
def poses_at(x0: float, y0: float, yaw0: float, lx: np.ndarray, ly: np.ndarray,
             dyaw: np.ndarray, ds: np.ndarray, scale: np.ndarray, bias: np.ndarray,
             at: np.ndarray) -> np.ndarray:
    """(calibrations, len(at), 3): the poses (x, y, unwrapped heading) at the indices ``at``
    of the steps ``lx, ly`` (robot frame), ``dyaw``, ``ds`` composed from ``(x0, y0, yaw0)``
    with each step's length times ``scale[j]`` and ``bias[j]`` per metre added to its
    rotation — ``Steps._integrate`` of ``drifted_many``, operation for operation."""
    m, n = scale.shape[0], lx.shape[0] + 1
    out = np.empty((m, at.shape[0], 3))
    px, py, ph = np.empty(n), np.empty(n), np.empty(n)
    for j in range(m):
        sc, b = scale[j], bias[j]
        turned, cx, cy = 0.0, 0.0, 0.0  # the cumulative sums, as numpy's cumsum adds them
        px[0], py[0], ph[0] = x0 + 0.0, y0 + 0.0, yaw0 + 0.0
        for i in range(n - 1):
            c, s = math.cos(ph[i]), math.sin(ph[i])
            sx, sy = lx[i] * sc, ly[i] * sc
            cx += c * sx - s * sy
            cy += s * sx + c * sy
            turned += dyaw[i] + b * ds[i]
            px[i + 1], py[i + 1], ph[i + 1] = x0 + cx, y0 + cy, yaw0 + turned
        for e in range(at.shape[0]):
            out[j, e, 0], out[j, e, 1], out[j, e, 2] = px[at[e]], py[at[e]], ph[at[e]]
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
