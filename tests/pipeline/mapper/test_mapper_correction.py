"""§4 feature correction with the free-space scan (eqs. 9-10)."""

from __future__ import annotations

import math

import numpy as np
from mapper_helpers import build_scan

from pipeline.config import MapperConfig
from pipeline.mapper.correction import correct_features, touched_features
from pipeline.mapper.features_reference import FeatureSet
from pipeline.mapper.free_space import free_space_scan
from pipeline.mapper.reading_features import classify_scan
from pipeline.mapper.types import MapperCounters

CFG = MapperConfig(method="andersone")


def _setup(grid, means, sigma, measured):  # type: ignore[no-untyped-def]
    fs = FeatureSet(grid, CFG.match_distance)
    n = len(means)
    fs.add(np.array(means, dtype=float), np.tile([sigma**2, 0.0, sigma**2], (n, 1)), np.zeros(n, dtype=np.int64))
    fs.measured[:n] = measured
    # One wide-open cone from (-3, 0) along +x, free up to 4.88 m.
    scan = build_scan([5.0], ox=-3.0, oy=0.0, max_range=6.0)
    free = free_space_scan(scan, classify_scan(scan, CFG), CFG, grid)
    return fs, free


def _run(fs, free, grid, seed=0):  # type: ignore[no-untyped-def]
    counters = MapperCounters()
    rng = np.random.Generator(np.random.PCG64(seed))
    correct_features(fs, free, CFG, grid, rng, counters)
    return counters


def test_feature_in_open_space_is_deleted(grid) -> None:  # type: ignore[no-untyped-def]
    fs, free = _setup(grid, [[0.0, 0.0]], 0.05, [1])
    c = _run(fs, free, grid)
    assert len(fs) == 0 and c.features_deleted == 1 and c.features_corrected == 0


def test_protected_feature_loses_one_count(grid) -> None:  # type: ignore[no-untyped-def]
    fs, free = _setup(grid, [[0.0, 0.0]], 0.05, [3])
    before = fs.table()
    c = _run(fs, free, grid)
    after = fs.table()
    assert c.features_protected == 1 and c.features_deleted == 0
    assert after.measured_times.tolist() == [2]
    assert (after.x[0], after.y[0], after.cov_xx[0]) == (before.x[0], before.y[0], before.cov_xx[0])


def test_half_covered_feature_moves_away_and_shrinks(grid) -> None:  # type: ignore[no-untyped-def]
    edge = math.radians(15.0)  # the cone's upper edge through (-3, 0)
    centre = [-3.0 + 3.0 * math.cos(edge), 3.0 * math.sin(edge)]
    sigma = 0.15
    fs, free = _setup(grid, [centre, [3.0, 4.0]], sigma, [1, 1])
    untouched = fs.table()
    c = _run(fs, free, grid)
    t = fs.table()
    assert c.features_corrected == 1 and len(t) == 2
    normal = np.array([-math.sin(edge), math.cos(edge)])  # pointing out of the cone
    shift = np.array([t.x[0] - centre[0], t.y[0] - centre[1]])
    # Half-normal mean is 0.80 σ; snapping to 5 cm cells blurs the edge a little.
    assert 0.5 * sigma < shift @ normal < 1.1 * sigma
    p = np.array([[t.cov_xx[0], t.cov_xy[0]], [t.cov_xy[0], t.cov_yy[0]]])
    assert normal @ p @ normal < 0.6 * sigma**2  # half-normal variance: 0.36 σ²
    assert 0.5 * (t.cov_xx[0] + t.cov_yy[0]) < sigma**2
    # The far feature is untouched, bit for bit.
    assert (t.x[1], t.y[1], t.cov_xx[1], t.cov_xy[1]) == (
        untouched.x[1], untouched.y[1], untouched.cov_xx[1], untouched.cov_xy[1]
    )


def test_touched_uses_exact_three_sigma(grid) -> None:  # type: ignore[no-untyped-def]
    # Cone from (-3,0) along +x, free to 4.88 m: features 0.2 m beyond the free tip, σ 0.05
    # (3σ = 0.15 m, no free centre within) and σ 0.1 (3σ = 0.3 m, reaches it).
    fs, free = _setup(grid, [[2.08, 0.0]], 0.05, [1])
    assert touched_features(fs, free, grid).size == 0
    fs2, free2 = _setup(grid, [[2.08, 0.0]], 0.1, [1])
    assert touched_features(fs2, free2, grid).tolist() == [0]


def _survivors(grid, free, centre, sigma, seed):  # type: ignore[no-untyped-def]
    """The same particle draws as correct_features, and which of them survive."""
    z = np.random.Generator(np.random.PCG64(seed)).standard_normal((2, 1, CFG.n_particles))
    px, py = centre[0] + sigma * z[0, 0], centre[1] + sigma * z[1, 0]
    col = np.floor((px - grid.origin_x) / grid.resolution).astype(np.int64)
    row = np.floor((py - grid.origin_y) / grid.resolution).astype(np.int64)
    keep = ~free.contains(row, col)
    assert 10 < keep.sum() < 190  # really cut
    return px, py, col, row, keep


def test_refit_uses_the_surviving_particles(grid) -> None:  # type: ignore[no-untyped-def]
    """Eqs. 9-10 on the survivors' own positions (the default), checked against a direct
    re-computation from the same particle draws; the cell decides only who survives."""
    centre, sigma = np.array([1.2, 0.95]), 0.12  # on the cone's upper edge, half cut
    fs, free = _setup(grid, [centre], sigma, [1])
    _run(fs, free, grid, seed=7)
    px, py, _, _, keep = _survivors(grid, free, centre, sigma, 7)
    t = fs.table()
    np.testing.assert_allclose([t.x[0], t.y[0]], [px[keep].mean(), py[keep].mean()], atol=1e-12)
    want = np.cov(np.stack([px[keep], py[keep]]))  # divisor M − 1
    np.testing.assert_allclose(
        [t.cov_xx[0], t.cov_xy[0], t.cov_yy[0]], [want[0, 0], want[0, 1], want[1, 1]], rtol=1e-9
    )


def test_refit_from_cell_centres_when_configured(grid) -> None:  # type: ignore[no-untyped-def]
    """refit_positions = 'cell': eqs. 9-10 on the survivors' cell centres."""
    centre, sigma = np.array([1.2, 0.95]), 0.12
    fs, free = _setup(grid, [centre], sigma, [1])
    cfg = MapperConfig(method="andersone", refit_positions="cell")
    correct_features(fs, free, cfg, grid, np.random.Generator(np.random.PCG64(7)), MapperCounters())
    _, _, col, row, keep = _survivors(grid, free, centre, sigma, 7)
    cx = grid.origin_x + (col[keep] + 0.5) * grid.resolution
    cy = grid.origin_y + (row[keep] + 0.5) * grid.resolution
    t = fs.table()
    np.testing.assert_allclose([t.x[0], t.y[0]], [cx.mean(), cy.mean()], rtol=0, atol=1e-12)
    want = np.cov(np.stack([cx, cy]))
    np.testing.assert_allclose(
        [t.cov_xx[0], t.cov_xy[0], t.cov_yy[0]], [want[0, 0], want[0, 1], want[1, 1]], rtol=1e-9
    )


def _wide_feature(grid, measured, split_guard):  # type: ignore[no-untyped-def]
    """A feature 1.2 m wide (σ_y = 0.6 m) across the cone at x = 0 (cone half-width 0.8 m):
    survivors on both sides, their mean in the cone."""
    cfg = MapperConfig(method="andersone", split_guard=split_guard)
    fs = FeatureSet(grid, cfg.match_distance)
    fs.add(np.array([[0.0, 0.0]]), np.array([[0.1**2, 0.0, 0.6**2]]), np.zeros(1, dtype=np.int64))
    fs.measured[0] = measured
    scan = build_scan([5.0], ox=-3.0, oy=0.0, max_range=6.0)
    free = free_space_scan(scan, classify_scan(scan, cfg), cfg, grid)
    counters = MapperCounters()
    correct_features(fs, free, cfg, grid, np.random.Generator(np.random.PCG64(0)), counters)
    return fs, counters


def test_split_guard_off_refits_across_the_cone(grid) -> None:  # type: ignore[no-untyped-def]
    fs, c = _wide_feature(grid, 1, split_guard=False)
    t = fs.table()
    assert (c.features_corrected, c.features_split, c.features_deleted) == (1, 0, 0)
    assert abs(t.y[0]) < 0.3 and t.cov_yy[0] > 0.6**2  # mean in the cone, spread grown


def test_split_guard_on_deletes_or_protects(grid) -> None:  # type: ignore[no-untyped-def]
    fs, c = _wide_feature(grid, 1, split_guard=True)
    assert len(fs) == 0
    assert (c.features_corrected, c.features_split, c.features_deleted) == (0, 1, 1)
    fs, c = _wide_feature(grid, 3, split_guard=True)
    t = fs.table()
    assert (c.features_split, c.features_protected, c.features_deleted) == (1, 1, 0)
    assert t.measured_times.tolist() == [2]
    assert (t.x[0], t.y[0], t.cov_yy[0]) == (0.0, 0.0, 0.6**2)  # unchanged


def _cone_free(grid):  # type: ignore[no-untyped-def]
    scan = build_scan([5.0], ox=-3.0, oy=0.0, max_range=6.0)
    return free_space_scan(scan, classify_scan(scan, CFG), CFG, grid)


def _free_cell_centre(grid, free, column):  # type: ignore[no-untyped-def]
    """Centre (x, y) of a free cell in window column ``column`` (0 = the first)."""
    rows = np.flatnonzero(free.mask[:, column])
    r = int(rows[len(rows) // 2])
    return (
        grid.origin_x + (free.col0 + column + 0.5) * grid.resolution,
        grid.origin_y + (free.row0 + r + 0.5) * grid.resolution,
    )


def test_touched_through_the_first_or_last_window_column_only(grid) -> None:  # type: ignore[no-untyped-def]
    """3σ = 0.105 m reaches a free cell centre 0.1 m away in the window's first (last)
    column, and no cell centre of the next column in (0.15 m)."""
    free = _cone_free(grid)
    w = free.mask.shape[1]
    for column, side in ((0, -1.0), (w - 1, 1.0)):
        x, y = _free_cell_centre(grid, free, column)
        for gap, touched in ((0.1, [0]), (0.12, [])):
            fs = FeatureSet(grid, CFG.match_distance)
            fs.add(np.array([[x + side * gap, y]]), np.array([[0.035**2, 0.0, 0.035**2]]),
                   np.zeros(1, dtype=np.int64))
            assert touched_features(fs, free, grid).tolist() == touched, (column, gap)


def test_bounding_box_overlap_without_ellipse_overlap_is_not_touched(grid) -> None:  # type: ignore[no-untyped-def]
    """Inside the free window's box, beside the narrow apex of the cone: the 3σ box meets
    the window, the ellipse meets no free cell."""
    free = _cone_free(grid)
    fs = FeatureSet(grid, CFG.match_distance)
    fs.add(np.array([[-2.5, 1.0]]), np.array([[0.05**2, 0.0, 0.05**2]]), np.zeros(1, dtype=np.int64))
    x_hi = grid.origin_x + (free.col0 + free.mask.shape[1]) * grid.resolution
    y_hi = grid.origin_y + (free.row0 + free.mask.shape[0]) * grid.resolution
    assert grid.origin_x + free.col0 * grid.resolution < -2.5 < x_hi and y_hi > 1.0  # in the box
    assert touched_features(fs, free, grid).size == 0


def test_keep_fraction_is_the_refit_threshold_itself(grid) -> None:  # type: ignore[no-untyped-def]
    """With M of N = 256 particles surviving (M/N exact in binary), keep_fraction = M/N
    refits and the next representable fraction above deletes."""
    centre, sigma, seed, n = np.array([1.2, 0.95]), 0.12, 7, 256
    free = _cone_free(grid)
    z = np.random.Generator(np.random.PCG64(seed)).standard_normal((2, 1, n))
    col = np.floor((centre[0] + sigma * z[0, 0] - grid.origin_x) / grid.resolution).astype(np.int64)
    row = np.floor((centre[1] + sigma * z[1, 0] - grid.origin_y) / grid.resolution).astype(np.int64)
    m = int((~free.contains(row, col)).sum())
    assert 10 < m < n - 10
    outcomes = {}
    for kf in (m / n, np.nextafter(m / n, 1.0)):
        cfg = MapperConfig(n_particles=n, keep_fraction=float(kf), split_guard=False)
        fs = FeatureSet(grid, cfg.match_distance)
        fs.add(centre[None, :], np.array([[sigma**2, 0.0, sigma**2]]), np.zeros(1, dtype=np.int64))
        fs.measured[:1] = 1
        counters = MapperCounters()
        correct_features(fs, free, cfg, grid, np.random.Generator(np.random.PCG64(seed)), counters)
        outcomes[kf] = (counters.features_corrected, counters.features_deleted, len(fs))
    assert list(outcomes.values()) == [(1, 0, 1), (0, 1, 0)]
