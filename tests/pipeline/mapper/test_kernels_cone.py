"""The compiled cone rasteriser (kernels/cone.py) against grid_raster.sector_spans and brute force."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mapper_helpers import cell_centres

from pipeline.mapper.grid_raster import sector_spans as numpy_sector_spans
from pipeline.mapper.kernels.cone import max_sector_spans, sector_spans
from pipeline.mapper.types import GridSpec

GRID = GridSpec(-5.0, -5.0, 0.05, 200, 200)


def _kernel_spans(ox, oy, alpha, hb, r_in, r_out, grid=GRID):  # type: ignore[no-untyped-def]
    cap = max_sector_spans(r_out, grid.resolution)
    rows, c0, c1 = (np.empty(cap, dtype=np.int64) for _ in range(3))
    n = sector_spans(ox, oy, alpha, hb, r_in, r_out, grid.origin_x, grid.origin_y,
                     grid.resolution, grid.width, grid.height, rows, c0, c1)
    return rows[:n], c0[:n], c1[:n]


def _cells(rows, c0, c1, grid=GRID):  # type: ignore[no-untyped-def]
    out = np.zeros(grid.shape, dtype=np.int64)
    for r, a, b in zip(rows.tolist(), c0.tolist(), c1.tolist(), strict=True):
        out[r, a : b + 1] += 1
    return out


def test_same_spans_as_numpy_reference_on_random_cones() -> None:
    rng = np.random.default_rng(11)
    n = 400
    ox, oy = rng.uniform(-6, 6, n), rng.uniform(-6, 6, n)  # some origins outside the grid
    alpha = rng.uniform(-7, 7, n)
    hb = rng.choice([0.0, 0.05, math.radians(15), math.radians(45), 1.6], n)
    radius = rng.uniform(0.0, 6.0, n)
    # Exact axis-aligned edges (a zero sine) too.
    alpha[:20] = np.repeat([0.0, 0.5 * math.pi, math.pi, -0.5 * math.pi], 5)
    hb[:20] = math.radians(15)
    ref = numpy_sector_spans(ox, oy, alpha, hb, radius, GRID)
    for k in range(n):
        rows, c0, c1 = _kernel_spans(ox[k], oy[k], alpha[k], hb[k], 0.0, radius[k])
        mine = ref.owner == k
        np.testing.assert_array_equal(rows, ref.row[mine])
        np.testing.assert_array_equal(c0, ref.c0[mine])
        np.testing.assert_array_equal(c1, ref.c1[mine])


@pytest.mark.parametrize(("alpha", "r_in", "r_out"), [(0.3, 1.0, 2.5), (2.0, 0.0, 1.2),
                                                       (-1.9, 2.9, 3.1), (1.571, 0.5, 4.0)])
def test_annular_sector_matches_brute_force(alpha: float, r_in: float, r_out: float) -> None:
    ox, oy, hb = 0.13, -0.41, math.radians(15)
    rows, c0, c1 = _kernel_spans(ox, oy, alpha, hb, r_in, r_out)
    got = _cells(rows, c0, c1)
    assert got.max() == 1  # no cell twice
    x, y = cell_centres(GRID)
    dist = np.hypot(x - ox, y - oy)
    off = np.abs(np.mod(np.arctan2(y - oy, x - ox) - alpha + np.pi, 2 * np.pi) - np.pi)
    truth = (dist >= r_in) & (dist < r_out) & (off <= hb)
    boundary = (np.abs(dist - r_in) < 1e-9) | (np.abs(dist - r_out) < 1e-9) | (np.abs(off - hb) < 1e-9)
    assert truth.sum() > 10
    assert not np.any((got.astype(bool) != truth) & ~boundary)


def test_inner_radius_splits_a_row_and_empty_sectors_write_nothing() -> None:
    # A wide cone looking along +x, inner radius 1 m: the origin's row keeps only far cells,
    # a row through the middle of the inner disk has no cells left of the disk (wedge).
    # A cone along +y, 80° each side of the axis, inner radius 1 m: the rows crossing the
    # inner disk keep the cells left and right of it, two spans.
    rows, c0, c1 = _kernel_spans(0.0, 0.0, 0.5 * math.pi, math.radians(80), 1.0, 2.0)
    assert np.all(np.diff(rows) >= 0)
    per_row = np.bincount(rows - rows.min())
    assert per_row.max() == 2
    two = np.flatnonzero(per_row == 2) + rows.min()
    centre_y = GRID.origin_y + (two + 0.5) * GRID.resolution
    assert centre_y.max() < 1.0  # only rows the inner disk reaches
    assert np.all(c1 >= c0)
    assert _kernel_spans(0.0, 0.0, 0.0, 0.3, 0.0, 0.0)[0].size == 0
    assert _kernel_spans(20.0, 20.0, 0.0, 0.3, 0.0, 2.0)[0].size == 0  # off the grid


def test_rows_at_once_equal_row_by_row_spans() -> None:
    # cone_row_spans (branch-free over a cone's rows) against cone_row_span, row by row:
    # random cones, edges along the axes (sin = 0, cos = ±1), rows past the cone and the
    # grid, cones clipped at the grid's sides.
    from pipeline.mapper.kernels.cone import cone_edges, cone_row_span, cone_row_spans

    rng = np.random.default_rng(7)
    gx, gy, res, width = -3.0, -2.0, 0.05, 90
    cases = [(rng.uniform(-5, 3), rng.uniform(-4, 4), rng.uniform(0.05, 4.0),
              rng.uniform(-math.pi, math.pi), rng.uniform(0.01, 1.6)) for _ in range(300)]
    cases += [(0.3, 0.1, 2.0, hb, hb) for hb in (0.2, 0.5)]  # the first edge along +x
    cases += [(0.3, 0.1, 2.0, -hb, hb) for hb in (0.2, 0.5)]  # the second edge along +x
    cases += [(0.3, 0.1, 2.0, math.pi - 0.3, 0.3), (0.3, 0.1, 2.0, -0.5 * math.pi, 0.5)]
    a_out, b_out = np.empty(400, dtype=np.int64), np.empty(400, dtype=np.int64)
    kept = empty = 0
    for ox, oy, radius, alpha, hb in cases:
        s1, c1, s2, c2, _, _ = cone_edges(alpha, hb)
        r0, r1 = -5, 150  # past the cone on both sides
        cone_row_spans(ox, oy, radius, s1, c1, s2, c2, r0, r1, gx, gy, res, width, a_out, b_out)
        for j in range(r1 - r0 + 1):
            a, b = cone_row_span(ox, oy, radius, s1, c1, s2, c2, r0 + j, gx, gy, res, width)
            if a > b:
                assert a_out[j] > b_out[j]
                empty += 1
            else:
                assert (a_out[j], b_out[j]) == (a, b)
                kept += 1
    assert kept > 5_000 and empty > 5_000
    assert any(cone_edges(a, h)[0] == 0.0 for _, _, _, a, h in cases)
