"""Wall lines estimated from the echoes' tangents (ALGORITHM.md §11, ``wall_line_half_length_m``).

Regions of constant depth (Leonard & Durrant-Whyte 1992): an echo of range r from a sonar
at p is tangent to the wall that answered it, the line of normal ψ (inside the cone) at
offset ``p·n(ψ) + r``, touched at ``p + r·n(ψ)``. Each echo votes once per direction bin
(:data:`LINE_BINS` over [0, π)) at its touching cell (:mod:`pipeline.mapper.kernels.lines`).
A wall seen from several places collects one bin's votes along one line; a single reading
gives one vote per bin, readings repeated from one place fall on one cell, and a wall's
tangents in a bin far from its normal (an oblique wall answered at the cone's edge) run
along the wall, not along the bin's line.

Per cell and bin, the bin's votes in the (2n + 1)² box around the cell (n = the half length
in cells) are summarised by their centre and second moments along the bin's normal (``n``)
and line (``t``). The cell lies on a wall line of that bin when

* the votes come from at least two distinct cells (two places agree),
* they form a line: spread across it ``σ_n ≤`` :data:`LINE_THICK` cells, along it
  ``σ_t ≥ 2·σ_n``, and their principal axis within half a bin of the bin's line
  (a sonar Hough peak in (ψ, d)),
* the cell lies on it (within one cell of the votes' offset along the normal);

its normal is that of the bin with the most votes among those. Memory: ``LINE_BINS`` uint16
grids. :func:`near_lines` spreads the lines' normals to the cells within
:data:`NEAR_LINE_M` (the scorer's tolerance).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from pipeline.mapper.kernels.lines import line_moments
from pipeline.mapper.types import F32, F64, B, GridSpec

LINE_BINS = 18  # direction bins of the normal line over [0, π): 10°, finer than a cone
LINE_THICK = 1.0  # spread of a line's votes across it, cells (σ)
NEAR_LINE_M = 0.10  # a cell this close to a wall line's cell is on the wall, m
# Votes on grid cells often meet a bound exactly (two votes along a grid axis lie half a bin
# off the bins' lines); such ties count as met, so rounding never decides: cells², rad, cells.
TIE = 1e-6
TILE = 64  # cells per side of the tiles the line test works in (any size gives the same lines)

Votes = npt.NDArray[np.uint16]


def empty_votes(grid: GridSpec) -> Votes:
    """The vote accumulator, ``(LINE_BINS, height, width)``."""
    return np.zeros((LINE_BINS, *grid.shape), dtype=np.uint16)


def wall_lines(votes: Votes, resolution: float, half_length_m: float) -> tuple[B, F32, F32]:
    """The cells on a wall line and its normal ``(on, nx, ny)`` (module doc).

    Worked tile by tile, and only where a bin has votes within the box's reach: the cost
    follows the cells the sonar saw, not the grid's extent (a 2 km corridor's grid is 95 %
    unseen)."""
    bins, h, w = votes.shape
    n = max(1, round(half_length_m / resolution))
    best: F64 = np.zeros((h, w))
    nx: F32 = np.zeros((h, w), dtype=np.float32)
    ny: F32 = np.zeros((h, w), dtype=np.float32)
    for b in range(bins):
        psi = (b + 0.5) * math.pi / bins
        for r0, c0 in _tiles_with_votes(votes[b], n):
            rows, cols = slice(r0, min(r0 + TILE, h)), slice(c0, min(c0 + TILE, w))
            # the tile and the n cells around it: every box around a tile cell lies inside
            top, left = max(r0 - n, 0), max(c0 - n, 0)
            outer = votes[b, top:rows.stop + n, left:cols.stop + n]
            m, ok = _line_test(outer.astype(np.float64), psi, n, bins)
            inner = (slice(r0 - top, rows.stop - top), slice(c0 - left, cols.stop - left))
            m, ok = m[inner], ok[inner] & (m[inner] > best[rows, cols])
            best[rows, cols] = np.where(ok, m, best[rows, cols])
            nx[rows, cols] = np.where(ok, np.float32(math.cos(psi)), nx[rows, cols])
            ny[rows, cols] = np.where(ok, np.float32(math.sin(psi)), ny[rows, cols])
    return best > 0, nx, ny


def _tiles_with_votes(v: Votes, n: int) -> list[tuple[int, int]]:
    """The corners of the :data:`TILE`-cell tiles with a vote within ``n`` cells."""
    h, w = v.shape
    th, tw = -(-h // TILE), -(-w // TILE)
    rr, cc = np.nonzero(v)
    if rr.size == 0:
        return []
    hit = np.zeros((th, tw), dtype=bool)
    for dr in (-n, 0, n):  # a vote reaches the tiles its (2n + 1)² box touches (n < TILE)
        for dc in (-n, 0, n):
            r, c = np.clip(rr + dr, 0, h - 1) // TILE, np.clip(cc + dc, 0, w - 1) // TILE
            hit[r, c] = True
    tr, tc = np.nonzero(hit)
    return [(int(i) * TILE, int(j) * TILE) for i, j in zip(tr, tc, strict=True)]


def _line_test(v: npt.NDArray[Any], psi: float, n: int, bins: int) -> tuple[F64, B]:
    """Each cell's box of votes ``m`` and whether the cell lies on their line (module doc),
    in coordinates local to ``v``. The box moments are compiled
    (:func:`~pipeline.mapper.kernels.lines.line_moments`: numpy's operations in its order,
    the same bits); the principal axis is numpy's ``arctan2`` of them."""
    m, _, var_n, var_t, cov, cells, off = line_moments(v, math.cos(psi), math.sin(psi), n)
    with np.errstate(invalid="ignore"):
        tilt = 0.5 * np.arctan2(2.0 * cov, var_t - var_n)  # principal axis off t
        ok: B = ((cells >= 2.0)
                 & (var_n <= LINE_THICK ** 2 + TIE) & (var_t >= 4.0 * var_n - TIE)
                 & (np.abs(tilt) <= 0.5 * math.pi / bins + TIE)
                 & (off <= 1.0 + TIE))
    return m, ok


def near_lines(on: B, nx: F32, ny: F32, radius_cells: float) -> tuple[B, F32, F32]:
    """The cells within ``radius_cells`` of a line cell, with the nearest one's normal
    (``scipy.ndimage`` imported here, on the lines' thread: not at the run's start)."""
    from scipy.ndimage import distance_transform_edt

    if not on.any():
        return np.zeros_like(on), np.zeros_like(nx), np.zeros_like(ny)
    dist, (ir, ic) = distance_transform_edt(~on, return_indices=True)
    near: B = dist <= radius_cells
    zero = np.float32(0.0)
    return near, np.where(near, nx[ir, ic], zero), np.where(near, ny[ir, ic], zero)
