"""Covariance ellipses on the grid as row spans (compiled twin of grid_raster.ellipse_spans).

A cell belongs to the ``k``σ ellipse of ``N(μ, P)`` when its centre has Mahalanobis
distance ≤ k; per row offset ``dy`` the chord is
``dx = (P_xy·dy ± sqrt(det P · (k²·P_yy − dy²))) / P_yy`` — the reference's arithmetic in
its order, with its clipping to the grid, so both give the same cells.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def ellipse_rows(my: float, cyy: float, k_sigma: float, gy: float, res: float,
                 height: int) -> tuple[int, int]:
    """First and last row (inclusive, clipped; empty when r1 < r0) of the ellipse's extent."""
    half_y = k_sigma * math.sqrt(max(cyy, 1e-300))
    r0 = np.ceil(((my - half_y) - gy) / res - 0.5)
    r1 = np.floor(((my + half_y) - gy) / res - 0.5)
    return int(min(max(r0, 0.0), float(height))), int(min(max(r1, -1.0), float(height - 1)))


@njit(cache=True)
def ellipse_row_span(mx: float, my: float, cxx: float, cxy: float, cyy: float, k_sigma: float,
                     row: int, gx: float, gy: float, res: float, width: int) -> tuple[int, int]:
    """Columns ``c0..c1`` of the ellipse on ``row``, clipped to the grid; empty when c0 > c1."""
    cyy_safe = max(cyy, 1e-300)
    dy = (gy + (row + 0.5) * res) - my
    det = max(cxx * cyy - cxy * cxy, 0.0)
    disc = det * (k_sigma * k_sigma * cyy - dy * dy)
    if not disc >= 0:
        return 0, -1
    root = math.sqrt(disc)
    centre = cxy * dy
    lo = (centre - root) / cyy_safe
    hi = (centre + root) / cyy_safe
    c0 = np.ceil(((mx + lo) - gx) / res - 0.5)
    c1 = np.floor(((mx + hi) - gx) / res - 0.5)
    if not (c0 <= c1 and c1 >= 0 and c0 <= width - 1):
        return 0, -1
    return int(min(max(c0, 0.0), width - 1.0)), int(min(max(c1, 0.0), width - 1.0))


@njit(cache=True)
def occupied_cells(mean: np.ndarray, cov: np.ndarray, k_sigma: float, gx: float, gy: float,
                   res: float, width: int, height: int, occ: np.ndarray) -> None:
    """Mark in ``occ`` (bool, grid shape) the cells of every feature's ``k``σ ellipse and
    the cell holding each in-grid mean (ALGORITHM.md §5, as occupancy.occupied_layer)."""
    for i in range(mean.shape[0]):
        mx = mean[i, 0]
        my = mean[i, 1]
        cxx = cov[i, 0]
        cxy = cov[i, 1]
        cyy = cov[i, 2]
        r0, r1 = ellipse_rows(my, cyy, k_sigma, gy, res, height)
        for row in range(r0, r1 + 1):
            c0, c1 = ellipse_row_span(mx, my, cxx, cxy, cyy, k_sigma, row, gx, gy, res, width)
            for c in range(c0, c1 + 1):
                occ[row, c] = True
        c = np.floor((mx - gx) / res)
        r = np.floor((my - gy) / res)
        if c >= 0 and c < width and r >= 0 and r < height:
            occ[int(r), int(c)] = True
