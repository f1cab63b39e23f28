"""Pose refinement's compiled kernels (pipeline/refine/kernels.py) against the numpy and
scipy they replace: the structure tensor read at a few cells, the free cones counted without
their samples' arrays, the densities' Gaussian blur — the same numbers bit for bit; the consistency's Gaussian weights and the
odometry summed per segment of travel — the same to rounding."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from pipeline.refine.kernels import (
    free_samples,
    gaussian_blur,
    gaussian_weights,
    structure_tensor_at,
)
from pipeline.refine.surfaces import TENSOR_SIGMA_CELLS, normal_angles, normal_angles_at


def _densities() -> list[np.ndarray]:
    """Random grids from 2 × 2 (smaller than the filter: reflected again and again) to
    40 × 40, raw and blurred like an echo density."""
    rng = np.random.default_rng(5)
    grids = []
    for h, w in ((2, 2), (2, 9), (5, 3), (13, 13), (40, 27), (31, 40)):
        raw = np.floor(rng.random((h, w)) * 4)
        grids += [raw, gaussian_filter(raw, 1.0, mode="constant", truncate=3.0)]
    return grids


@pytest.mark.parametrize("density", _densities(), ids=lambda d: f"{d.shape[0]}x{d.shape[1]}")
def test_the_structure_tensor_at_cells_is_the_whole_grid_filter_bit_for_bit(
        density: np.ndarray) -> None:
    gy, gx = np.gradient(density)
    whole = [gaussian_filter(v, TENSOR_SIGMA_CELLS) for v in (gx * gx, gy * gy, gx * gy)]
    rows, cols = (v.ravel() for v in np.indices(density.shape))  # every cell, edges too
    at = structure_tensor_at(gx, gy, rows, cols, gaussian_weights(TENSOR_SIGMA_CELLS, 4.0))
    for k in range(3):
        assert np.array_equal(at[:, k], whole[k].ravel())


@pytest.mark.parametrize("sd", [1.0, 0.5, 2.0, 1.5])
@pytest.mark.parametrize("density", _densities(), ids=lambda d: f"{d.shape[0]}x{d.shape[1]}")
def test_the_blur_is_scipys_constant_mode_gaussian_filter_bit_for_bit(
        density: np.ndarray, sd: float) -> None:
    blurred = gaussian_blur(density, sd)
    assert blurred.shape == density.shape
    assert np.array_equal(blurred, gaussian_filter(density, sd, mode="constant", truncate=3.0))


def test_the_blur_spreads_a_unit_over_the_weights_and_loses_what_falls_outside() -> None:
    grid = np.zeros((9, 9))
    grid[4, 4] = 1.0
    w = gaussian_weights(1.0)  # radius 3
    assert np.allclose(gaussian_blur(grid, 1.0)[1:8, 1:8], np.outer(w, w), rtol=0, atol=1e-17)
    edge = np.zeros((9, 9))
    edge[0, 4] = 1.0  # half the blur falls off the grid (zeros beyond it, nothing reflected)
    assert gaussian_blur(edge, 1.0).sum() == pytest.approx(w[3:].sum(), abs=1e-15)


def test_the_normals_at_cells_are_the_whole_grids_and_point_across_a_wall() -> None:
    density = np.zeros((60, 40))
    density[:, 20] = 1.0  # a wall along the rows (y): its normal is along x
    density = gaussian_filter(density, 1.0, mode="constant", truncate=3.0)
    rows = np.array([30, 20, 30, 40, 0])  # a cell asked twice, a corner
    cols = np.array([20, 19, 20, 21, 0])
    angles = normal_angles_at(density, rows, cols)
    assert np.array_equal(angles, normal_angles(density)[rows, cols])
    assert np.abs(angles[:4]).max() < 1e-12  # across the wall: angle 0 (x), modulo π


def _numpy_free_samples(ox: np.ndarray, oy: np.ndarray, rx: np.ndarray, ry: np.ndarray,
                        range_m: np.ndarray, steps: np.ndarray, band: float
                        ) -> tuple[np.ndarray, np.ndarray]:
    """The samples as the association built them in numpy (the reference)."""
    free = steps[None, None, :] < (range_m[:, None, None] - band)
    free = np.broadcast_to(free, (*rx.shape, steps.size))
    frac = steps[None, None, :] / range_m[:, None, None]
    fx = (ox[:, None, None] + (rx - ox[:, None])[..., None] * frac)[free]
    fy = (oy[:, None, None] + (ry - oy[:, None])[..., None] * frac)[free]
    return fx, fy


def test_the_free_cones_are_counted_where_numpy_places_their_samples() -> None:
    rng = np.random.default_rng(8)
    n, cell = 300, 0.1
    ox, oy = rng.uniform(-3, 3, n), rng.uniform(-3, 3, n)
    range_m = rng.uniform(0.15, 4.0, n)  # some shorter than the band: no sample
    heading = rng.uniform(-math.pi, math.pi, n)[:, None] + np.array([-0.26, 0.0, 0.26])
    rx, ry = ox[:, None] + range_m[:, None] * np.cos(heading), oy[:, None] + range_m[:, None] * np.sin(heading)
    steps = np.arange(1, int(range_m.max() / cell) + 1) * cell
    fx, fy = _numpy_free_samples(ox, oy, rx, ry, range_m, steps, 0.2)
    box = free_samples(ox, oy, rx, ry, range_m, steps, 0.2, 0.0, 0.0, cell, np.zeros((0, 0)))
    assert box == (fx.min(), fy.min(), fx.max(), fy.max())
    x0, y0 = box[0] - 0.5, box[1] - 0.5
    h, w = 60, 50  # smaller than the samples' box: the far ones clipped to the edge
    r = np.clip(((fy - y0) / cell).astype(np.int64), 0, h - 1)
    c = np.clip(((fx - x0) / cell).astype(np.int64), 0, w - 1)
    reference = np.bincount(r * w + c, minlength=h * w).reshape(h, w).astype(np.float64)
    counts = np.zeros((h, w))
    assert free_samples(ox, oy, rx, ry, range_m, steps, 0.2, x0, y0, cell, counts) == box
    assert counts.sum() == fx.size > 0
    assert np.array_equal(counts, reference)


def test_no_free_sample_gives_an_empty_box_and_no_count() -> None:
    one = np.zeros(1)
    ray = np.array([[0.1, 0.1, 0.1]])
    steps = np.array([0.1])
    counts = np.zeros((3, 3))
    assert free_samples(one, one, ray, ray, np.array([0.15]), steps, 0.2, -1.0, -1.0, 0.1,
                        counts) == (math.inf, math.inf, -math.inf, -math.inf)
    assert counts.sum() == 0.0


@pytest.mark.parametrize("sd", [1.0, 0.4, 2.5, 0.05])  # 0.05: the first weight underflows
@pytest.mark.parametrize("u", [0.0, 3.25, -7.999, 12.5])
def test_the_gaussian_weights_at_a_point_are_each_cells_exponential(u: float, sd: float) -> None:
    from pipeline.refine.kernels import gaussian_at

    rad = 4
    out = np.empty(2 * rad + 2)
    c0 = gaussian_at(u, rad, sd, out)
    assert c0 == math.floor(u) - rad
    d = u - (c0 + np.arange(2 * rad + 2))
    want = np.exp(-0.5 * d * d / (sd * sd))
    assert np.allclose(out, want / want.sum(), rtol=1e-12, atol=1e-300)
    assert out.sum() == pytest.approx(1.0, abs=1e-14)


def test_a_segment_sum_stops_where_its_taylor_series_would_not_hold() -> None:
    from pipeline.refine.kernels import MAX_TURN, SEGMENT_M, poses_at, step_segments

    # a straight metre in 100 steps, then a quarter turn on the spot, then another metre
    lx = np.concatenate([np.full(100, 0.01), [0.0], np.full(100, 0.01)])
    dyaw = np.concatenate([np.zeros(100), [math.pi / 2], np.zeros(100)])
    ly, ds = np.zeros_like(lx), lx.copy()
    at = np.array([0, 50, 100, 101, 201])
    seg = step_segments(0.0, lx, ly, dyaw, ds, at)
    bounds = seg[2]
    assert bounds[0] == 0 and bounds[-1] == 201 and 100 in bounds and 101 not in bounds
    assert np.diff(seg[0][bounds]).max() <= SEGMENT_M + 0.01
    big = 4 * MAX_TURN / SEGMENT_M  # turns a half-metre segment's steps by 2 × MAX_TURN
    out = poses_at(0.0, 0.0, *seg, np.ones(3), np.array([0.0, 0.01, big]))
    assert out.shape == (3, 5, 3)
    assert np.allclose(out[0, :, :2], [[0, 0], [0.5, 0], [1, 0], [1, 0], [1, 1]])
    assert np.allclose(out[0, :, 2], [0, 0, 0, math.pi / 2, math.pi / 2])
    for j, b in ((1, 0.01), (2, big)):  # each step turned by b per metre before it
        heading = np.concatenate([[0.0], np.cumsum(dyaw + b * ds)])
        px = np.concatenate([[0.0], np.cumsum(np.cos(heading[:-1]) * lx)])
        py = np.concatenate([[0.0], np.cumsum(np.sin(heading[:-1]) * lx)])
        assert np.abs(out[j, :, 0] - px[at]).max() < 1e-12
        assert np.abs(out[j, :, 1] - py[at]).max() < 1e-12
        assert np.abs(out[j, :, 2] - heading[at]).max() < 1e-12


def test_the_headings_are_wrapped_as_numpy_wraps_them_bit_for_bit() -> None:
    from formats.angles import wrap_angle
    from pipeline.refine.kernels import poses_at, step_segments

    # three and a half turns on a 2 m circle: headings far beyond ±π before wrapping
    n = 700
    lx, ly = np.full(n, 0.04), np.zeros(n)
    dyaw, ds = np.full(n, 7 * math.pi / n), np.full(n, 0.04)
    at = np.arange(0, n + 1, 7)
    seg = step_segments(0.3, lx, ly, dyaw, ds, at)
    bias = np.array([0.0, 0.02, -0.5])
    out = poses_at(0.0, 0.0, *seg, np.ones(3), bias)
    unwrapped = seg[7][None, :] + bias[:, None] * seg[8][None, :]  # Φ + b·S at each pose
    assert np.abs(unwrapped).max() > 6 * math.pi
    assert (out[..., 2] >= -math.pi).all() and (out[..., 2] < math.pi).all()
    assert np.array_equal(out[..., 2], wrap_angle(unwrapped))


def test_the_blurred_pair_sums_rows_then_columns_in_order_bit_for_bit() -> None:
    from pipeline.refine.kernels import blurred_pair

    rng = np.random.default_rng(11)
    hits, frees = rng.random((20, 24)) * 3, rng.random((20, 24)) * 5
    wu, wv = rng.random(10), rng.random(10)
    for r0, c0 in ((0, 0), (3, 7), (10, 14)):
        hh = ff = 0.0
        for m in range(10):  # each row's sum over q in order, then the rows' in order
            sh = sf = 0.0
            for q in range(10):
                sh += wu[q] * hits[r0 + m, c0 + q]
                sf += wu[q] * frees[r0 + m, c0 + q]
            hh += wv[m] * sh
            ff += wv[m] * sf
        assert blurred_pair(hits, frees, wu, wv, r0, c0) == (hh, ff)


def test_the_placed_consistency_places_as_transform_points_bit_for_bit() -> None:
    from pipeline.refine.kernels import consistency_placed, consistency_score
    from pipeline.se2 import transform_points

    rng = np.random.default_rng(12)
    n = 400
    pose = np.column_stack([rng.uniform(-2, 2, n), rng.uniform(-2, 2, n),
                            rng.uniform(-math.pi, math.pi, n)])
    sx, sy = rng.uniform(-0.2, 0.2, n), rng.uniform(-0.2, 0.2, n)
    reach = rng.uniform(0.5, 3.0, n)[:, None]
    spread = np.array([-0.2, -0.1, 0.0, 0.1, 0.2])
    bx, by = sx[:, None] + reach * np.cos(spread), sy[:, None] + reach * np.sin(spread)
    steps = np.arange(1, 31) * 0.1
    args = (steps, 0.2, 0.1, 0.4, 1.0, 4, 2.0)
    wx, wy = transform_points(pose[:, None, :], bx, by)
    ox, oy = transform_points(pose, sx, sy)
    want = consistency_score(np.ascontiguousarray(wx), np.ascontiguousarray(wy), ox, oy, *args)
    got = consistency_placed(np.ascontiguousarray(pose[:, 0]), np.ascontiguousarray(pose[:, 1]),
                             np.cos(pose[:, 2]), np.sin(pose[:, 2]), bx, by, sx, sy, *args)
    assert 0.0 < got < 1.0
    assert got == want


def test_the_normal_equations_are_the_dense_products() -> None:
    """kernels.normal_equations: JᵀJ and Jᵀf of the row-weighted CSR matrix, as numpy's
    dense products (entries that share a row and column, and empty rows, included)."""
    from scipy.sparse import csr_matrix

    from pipeline.refine.kernels import normal_equations

    rng = np.random.default_rng(4)
    dense = np.where(rng.uniform(size=(40, 12)) < 0.2, rng.normal(size=(40, 12)), 0.0)
    dense[5] = 0.0
    m = csr_matrix(dense)
    w, f = rng.uniform(0.1, 2.0, 40), rng.normal(size=40)
    a, g = normal_equations(m.indptr.astype(np.int64), m.indices.astype(np.int64), m.data,
                            w, f, 12)
    j = w[:, None] * m.toarray()
    np.testing.assert_allclose(a, j.T @ j, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(g, j.T @ f, rtol=1e-12, atol=1e-14)
    assert np.array_equal(a, a.T)
