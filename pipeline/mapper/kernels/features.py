"""The feature set's storage and spatial hash grid, and the Kalman merge, compiled.

The compiled twin of :class:`pipeline.mapper.features_reference.FeatureSet` (the numpy reference):
the same columns, the same buckets (``match_distance`` wide, or wider on huge grids, over
the map grid; points outside fall into the clamped border buckets), the same arithmetic.
A bucket lists its slots as a doubly linked list (``head``, ``nxt``, ``prv``), so linking
and unlinking are O(1); the nearest-feature query walks the 3×3 buckets around a point
(ties → lowest slot = lowest id, as the reference). Slots are appended in id order and
compacted stably when half the store is dead, so slot order stays id order.

Readings merge one at a time in row order — the sequential semantics the reference
reproduces with its vectorised rounds (ALGORITHM.md §2; feature_set module doc).
Capacity is the caller's job (:class:`pipeline.mapper.features.FeatureStore` reserves
room for a whole group of scans before a kernel call); kernels never reallocate.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

# Positions in FeatureArrays.meta.
N_SLOTS, NEXT_ID, LIVE = 0, 1, 2


class FeatureArrays(NamedTuple):
    """The store's arrays (capacity rows), shared by Python and the kernels."""

    mean: np.ndarray  # (cap, 2) m
    cov: np.ndarray  # (cap, 3) xx, xy, yy, m²
    box: np.ndarray  # (cap, 4) 3σ box as x_hi, −x_lo, y_hi, −y_lo (dead: −inf)
    measured: np.ndarray  # int64
    first_ns: np.ndarray
    last_ns: np.ndarray
    merges: np.ndarray
    ids: np.ndarray  # int64, -1 for unused slots
    alive: np.ndarray  # bool
    bucket: np.ndarray  # int64: bucket of a linked slot, -1 otherwise
    nxt: np.ndarray  # int64: next slot in the bucket's list, -1 at the end
    prv: np.ndarray  # int64: previous slot, -1 at the head
    head: np.ndarray  # (buckets,) int64: first slot of each bucket, -1 when empty
    meta: np.ndarray  # int64 [slots in use, next id, live features]
    geometry: np.ndarray  # float64 [origin x, origin y, 1/bucket size, last bx, last by, nbx, nby]


@njit(cache=True)
def bucket_xy(fa: FeatureArrays, x: float, y: float) -> tuple[int, int]:
    """Bucket column and row of a point (clamped to the bucket grid)."""
    g = fa.geometry
    fx = (x - g[0]) * g[2]
    fy = (y - g[1]) * g[2]
    bx = math.floor(min(max(fx, 0.0), g[3]))
    by = math.floor(min(max(fy, 0.0), g[4]))
    return bx, by


@njit(cache=True)
def link(fa: FeatureArrays, s: int, b: int) -> None:
    """Put slot ``s`` at the head of bucket ``b``'s list."""
    first = fa.head[b]
    fa.nxt[s] = first
    fa.prv[s] = -1
    if first >= 0:
        fa.prv[first] = s
    fa.head[b] = s
    fa.bucket[s] = b


@njit(cache=True)
def unlink(fa: FeatureArrays, s: int) -> None:
    """Take slot ``s`` out of its bucket's list."""
    b = fa.bucket[s]
    p = fa.prv[s]
    q = fa.nxt[s]
    if p >= 0:
        fa.nxt[p] = q
    else:
        fa.head[b] = q
    if q >= 0:
        fa.prv[q] = p
    fa.bucket[s] = -1


@njit(cache=True)
def set_gaussian(fa: FeatureArrays, s: int, mx: float, my: float, cxx: float, cxy: float,
                 cyy: float) -> None:
    """Mean, covariance and 3σ box of slot ``s`` (the reference's ``_set_gaussians``)."""
    fa.mean[s, 0] = mx
    fa.mean[s, 1] = my
    fa.cov[s, 0] = cxx
    fa.cov[s, 1] = cxy
    fa.cov[s, 2] = cyy
    hx = 3.0 * math.sqrt(cxx)
    hy = 3.0 * math.sqrt(cyy)
    fa.box[s, 0] = mx + hx
    fa.box[s, 1] = -(mx - hx)
    fa.box[s, 2] = my + hy
    fa.box[s, 3] = -(my - hy)


@njit(cache=True)
def add_feature(fa: FeatureArrays, mx: float, my: float, cxx: float, cxy: float, cyy: float,
                t_ns: int) -> int:
    """Append a new feature (measured_times = 1); returns its slot."""
    s = fa.meta[N_SLOTS]
    set_gaussian(fa, s, mx, my, cxx, cxy, cyy)
    fa.measured[s] = 1
    fa.first_ns[s] = t_ns
    fa.last_ns[s] = t_ns
    fa.merges[s] = 0
    fa.ids[s] = fa.meta[NEXT_ID]
    fa.alive[s] = True
    fa.meta[N_SLOTS] += 1
    fa.meta[NEXT_ID] += 1
    fa.meta[LIVE] += 1
    bx, by = bucket_xy(fa, mx, my)
    link(fa, s, by * int(fa.geometry[5]) + bx)
    return s


@njit(cache=True)
def move_feature(fa: FeatureArrays, s: int, mx: float, my: float, cxx: float, cxy: float,
                 cyy: float) -> None:
    """Replace slot ``s``'s Gaussian, re-bucketing it when its bucket changes."""
    set_gaussian(fa, s, mx, my, cxx, cxy, cyy)
    bx, by = bucket_xy(fa, mx, my)
    b = by * int(fa.geometry[5]) + bx
    if b != fa.bucket[s]:
        unlink(fa, s)
        link(fa, s, b)


@njit(cache=True)
def delete_feature(fa: FeatureArrays, s: int) -> None:
    """Remove the feature in slot ``s`` (compaction is :func:`compact_if_half_dead`'s)."""
    unlink(fa, s)
    fa.alive[s] = False
    for i in range(4):
        fa.box[s, i] = -np.inf
    fa.meta[LIVE] -= 1


@njit(cache=True)
def compact_if_half_dead(fa: FeatureArrays) -> None:
    """Drop dead slots (stably, so slot order stays id order) when they are half the store."""
    n = fa.meta[N_SLOTS]
    dead = n - fa.meta[LIVE]
    if dead < 1024 or 2 * dead < n:
        return
    for s in range(n):
        if fa.bucket[s] >= 0:
            fa.head[fa.bucket[s]] = -1
            fa.bucket[s] = -1
    m = 0
    for s in range(n):
        if not fa.alive[s]:
            continue
        if m != s:
            fa.mean[m] = fa.mean[s]
            fa.cov[m] = fa.cov[s]
            fa.box[m] = fa.box[s]
            fa.measured[m] = fa.measured[s]
            fa.first_ns[m] = fa.first_ns[s]
            fa.last_ns[m] = fa.last_ns[s]
            fa.merges[m] = fa.merges[s]
            fa.ids[m] = fa.ids[s]
            fa.alive[m] = True
        m += 1
    for s in range(m, n):
        fa.alive[s] = False
        fa.ids[s] = -1
        for i in range(4):
            fa.box[s, i] = -np.inf
    nbx = int(fa.geometry[5])
    # Linked in descending slot order so each list reads ascending (not needed for the
    # results, which break ties by slot, but it keeps walks cache-friendly).
    for s in range(m - 1, -1, -1):
        bx, by = bucket_xy(fa, fa.mean[s, 0], fa.mean[s, 1])
        link(fa, s, by * nbx + bx)
    fa.meta[N_SLOTS] = m


@njit(cache=True)
def nearest_feature(fa: FeatureArrays, x: float, y: float) -> tuple[int, float]:
    """Slot of the nearest live feature among the 3×3 buckets around ``(x, y)`` (ties →
    lowest slot) and its distance, m; ``(-1, inf)`` when there is none."""
    nbx = int(fa.geometry[5])
    nby = int(fa.geometry[6])
    bx, by = bucket_xy(fa, x, y)
    best = np.inf
    best_s = -1
    for oy in range(-1, 2):
        ry = min(max(by + oy, 0), nby - 1)
        for ox in range(-1, 2):
            rx = min(max(bx + ox, 0), nbx - 1)
            s = fa.head[ry * nbx + rx]
            while s >= 0:
                d = math.hypot(fa.mean[s, 0] - x, fa.mean[s, 1] - y)
                if d < best or (d == best and s < best_s):
                    best = d
                    best_s = s
                s = fa.nxt[s]
    return best_s, best


@njit(cache=True)
def kalman_merge_into(fa: FeatureArrays, s: int, zx: float, zy: float, zxx: float, zxy: float,
                      zyy: float) -> None:
    """Eqs. 5-8 into slot ``s`` (the reference ``kalman_merge``'s arithmetic, in its order)."""
    fxx = fa.cov[s, 0]
    fxy = fa.cov[s, 1]
    fyy = fa.cov[s, 2]
    sxx = fxx + zxx
    sxy = fxy + zxy
    syy = fyy + zyy
    det = sxx * syy - sxy * sxy
    ixx = syy / det
    ixy = -sxy / det
    iyy = sxx / det
    k11 = fxx * ixx + fxy * ixy
    k12 = fxx * ixy + fxy * iyy
    k21 = fxy * ixx + fyy * ixy
    k22 = fxy * ixy + fyy * iyy
    nx = zx - fa.mean[s, 0]
    ny = zy - fa.mean[s, 1]
    mx = fa.mean[s, 0] + k11 * nx + k12 * ny
    my = fa.mean[s, 1] + k21 * nx + k22 * ny
    a11 = 1.0 - k11
    a12 = -k12
    a21 = -k21
    a22 = 1.0 - k22
    pxx = a11 * fxx + a12 * fxy
    pxy = a11 * fxy + a12 * fyy
    pyx = a21 * fxx + a22 * fxy
    pyy = a21 * fxy + a22 * fyy
    move_feature(fa, s, mx, my, pxx, 0.5 * (pxy + pyx), pyy)


@njit(cache=True)
def merge_readings(fa: FeatureArrays, mean: np.ndarray, cov: np.ndarray, t_ns: np.ndarray,
                   lo: int, hi: int, match_distance: float) -> tuple[int, int]:
    """Merge reading features ``lo:hi`` in row order (§2); returns ``(created, merged)``."""
    created = 0
    merged = 0
    for j in range(lo, hi):
        x = mean[j, 0]
        y = mean[j, 1]
        s, d = nearest_feature(fa, x, y)
        if d < match_distance:
            kalman_merge_into(fa, s, x, y, cov[j, 0], cov[j, 1], cov[j, 2])
            fa.measured[s] += 1
            fa.merges[s] += 1
            fa.last_ns[s] = t_ns[j]
            merged += 1
        else:
            add_feature(fa, x, y, cov[j, 0], cov[j, 1], cov[j, 2], t_ns[j])
            created += 1
    return created, merged


@njit(cache=True)
def add_features(fa: FeatureArrays, mean: np.ndarray, cov: np.ndarray, t_ns: np.ndarray) -> None:
    """Append each row as a new feature (measured_times = 1), in row order."""
    for j in range(mean.shape[0]):
        add_feature(fa, mean[j, 0], mean[j, 1], cov[j, 0], cov[j, 1], cov[j, 2], t_ns[j])
