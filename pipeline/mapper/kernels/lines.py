"""Compiled Hough vote of the echoes' tangent lines (ALGORITHM.md §11, wall lines).

An echo of range ``r`` from a sonar at ``(ox, oy)`` is tangent to the wall that answered
it: for every line normal ψ inside the cone the wall may be the line of normal ψ touched at
``(ox, oy) + r·(cos ψ, sin ψ)``. Per reading, each direction bin's centre ψ inside the cone
(``bins`` equal bins of the normal line over [0, π); a centre on the cone's edge counts) adds one vote at its touching cell in
``votes[bin]`` (saturating). Deterministic.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

from pipeline.mapper.types import F64

EDGE = 1e-9  # bins: a cone edge this close to a bin's centre reaches it (rounding, not physics)


@njit(cache=True)
def vote_tangents(ox: F64, oy: F64, alpha: F64, half: F64, r: F64, gx: float, gy: float,
                  res: float, votes: npt.NDArray[np.uint16]) -> None:
    """Add each echo's tangent votes to ``votes`` (``(bins, height, width)``, uint16)."""
    bins, height, width = votes.shape
    step = math.pi / bins
    for i in range(len(r)):
        if not r[i] > 0.0:
            continue
        # A bin centre on the cone's edge is inside: mounting angles and beam widths in
        # whole degrees put edges on centres, and a yaw read from a quaternion or from
        # text differs in its last bits (EDGE keeps every log format's votes the same).
        j0 = math.ceil((alpha[i] - half[i]) / step - 0.5 - EDGE)
        j1 = math.floor((alpha[i] + half[i]) / step - 0.5 + EDGE)
        for j in range(j0, j1 + 1):
            psi = (j + 0.5) * step
            col = math.floor((ox[i] + r[i] * math.cos(psi) - gx) / res)
            row = math.floor((oy[i] + r[i] * math.sin(psi) - gy) / res)
            if 0 <= row < height and 0 <= col < width:
                b = j % bins
                if votes[b, row, col] < 65535:
                    votes[b, row, col] += 1


@njit(cache=True, inline="always")
def _prefix(a: F64, p: F64, n: int) -> None:
    """``p`` (``(h + 2n + 1, w + 2n + 1)``, zeros in row and column 0) = the sums of ``a``
    zero-padded by ``n`` over every top-left rectangle: numpy's ``cumsum`` along the rows,
    then along the columns, term by term in their order (the same bits)."""
    h, w = a.shape
    hp, wp = h + 2 * n, w + 2 * n
    for i in range(hp):  # the running sums down each column
        for j in range(wp):
            r, c = i - n, j - n
            x = a[r, c] if 0 <= r < h and 0 <= c < w else 0.0
            p[i + 1, j + 1] = p[i, j + 1] + x if i > 0 else x
    for i in range(hp):  # then along each row
        for j in range(1, wp):
            p[i + 1, j + 1] = p[i + 1, j] + p[i + 1, j + 1]


@njit(cache=True, inline="always")
def _box(p: F64, n: int, i: int, j: int) -> float:
    """The sum over the ``(2n + 1)²`` box around cell ``(i, j)`` from :func:`_prefix`'s
    ``p``, as ``specular.box_sum`` combines its corners."""
    k = 2 * n + 1
    return p[i + k, j + k] - p[i, j + k] - p[i + k, j] + p[i, j]


@njit(cache=True, nogil=True, error_model="numpy")
def line_moments(v: F64, c: float, s: float, n: int) -> tuple[F64, F64, F64, F64, F64, F64,
                                                                  F64]:
    """Per cell of the vote tile ``v``, the moments of the votes in its ``(2n + 1)²`` box
    along the normal ``(c, s)`` (``on_n``) and the line (``on_t``), as
    :func:`pipeline.mapper.wall_lines._line_test` defines them: ``(m, mn, var_n, var_t,
    cov, cells voted, |on_n − mn|)``, each with numpy's operations in numpy's order (box
    sums of ``specular.box_sum``: the same bits)."""
    h, w = v.shape
    on_n = np.empty((h, w))
    on_t = np.empty((h, w))
    for i in range(h):
        for j in range(w):
            on_n[i, j] = float(j) * c + float(i) * s
            on_t[i, j] = float(i) * c - float(j) * s
    terms = np.empty((7, h, w))
    for i in range(h):
        for j in range(w):
            x, a, b = v[i, j], on_n[i, j], on_t[i, j]
            terms[0, i, j] = x
            terms[1, i, j] = x * a
            terms[2, i, j] = x * b
            terms[3, i, j] = x * a * a
            terms[4, i, j] = x * b * b
            terms[5, i, j] = x * a * b
            terms[6, i, j] = 1.0 if x > 0 else 0.0
    p = np.zeros((7, h + 2 * n + 1, w + 2 * n + 1))
    for t in range(7):
        _prefix(terms[t], p[t], n)
    m = np.empty((h, w))
    mn = np.empty((h, w))
    var_n = np.empty((h, w))
    var_t = np.empty((h, w))
    cov = np.empty((h, w))
    cells = np.empty((h, w))
    off = np.empty((h, w))
    for i in range(h):
        for j in range(w):
            mm = _box(p[0], n, i, j)
            a = _box(p[1], n, i, j) / mm
            b = _box(p[2], n, i, j) / mm
            m[i, j] = mm
            mn[i, j] = a
            var_n[i, j] = _box(p[3], n, i, j) / mm - a * a
            var_t[i, j] = _box(p[4], n, i, j) / mm - b * b
            cov[i, j] = _box(p[5], n, i, j) / mm - a * b
            cells[i, j] = _box(p[6], n, i, j)
            off[i, j] = abs(on_n[i, j] - a)
    return m, mn, var_n, var_t, cov, cells, off
