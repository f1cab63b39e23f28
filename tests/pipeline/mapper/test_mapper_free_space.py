"""§3 free-space scan and the shape rasterisers, against brute force over cell centres."""

from __future__ import annotations

import math

import numpy as np
from mapper_helpers import build_scan, cell_centres

from formats.map_types import GridSpec
from pipeline.config import MapperConfig
from pipeline.mapper import AndersoneMapper
from pipeline.mapper.free_space import free_space_scan, free_space_scans
from pipeline.mapper.grid_raster import ellipse_spans, span_cells
from pipeline.mapper.reading_features import classify_scan
from pipeline.mapper.types import Scan

CFG = MapperConfig(method="andersone")
HB = math.radians(15.0)


def _free(scan, grid, cfg=CFG):  # type: ignore[no-untyped-def]
    return free_space_scan(scan, classify_scan(scan, cfg), cfg, grid)


def _cone_truth(grid, ox, oy, alpha, radius):  # type: ignore[no-untyped-def]
    x, y = cell_centres(grid)
    dist = np.hypot(x - ox, y - oy)
    off = np.abs(np.mod(np.arctan2(y - oy, x - ox) - alpha + np.pi, 2 * np.pi) - np.pi)
    return dist, off, (dist < radius) & (off <= HB)


def test_cone_matches_brute_force_and_area(grid) -> None:  # type: ignore[no-untyped-def]
    d, alpha, ox, oy = 3.0, 0.4, 0.12, -0.3
    free = _free(build_scan([d], alpha=alpha, ox=ox, oy=oy), grid)
    radius = d - 2.0 * (0.01 + 0.01 * d)
    dist, off, truth = _cone_truth(grid, ox, oy, alpha, radius)
    got = np.zeros(grid.shape, dtype=bool)
    got.reshape(-1)[free.cells] = True
    # Identical except for cells within rounding of the boundary.
    boundary = (np.abs(dist - radius) < 1e-9) | (np.abs(off - HB) < 1e-9)
    assert not np.any((got != truth) & ~boundary)
    # Nothing at distance ≥ d − m_free, nothing outside the beam.
    assert dist[got].max() < radius + 1e-9
    assert off[got].max() <= HB + 1e-9
    area_cells = 0.5 * radius**2 * (2 * HB) / grid.resolution**2
    assert abs(free.count - area_cells) / area_cells < 0.03
    assert free.count == int(got.sum())


def test_union_counts_each_cell_once(grid) -> None:  # type: ignore[no-untyped-def]
    one = _free(build_scan([2.0]), grid)
    two = _free(build_scan([2.0, 2.0]), grid)
    assert two.count == one.count > 0
    np.testing.assert_array_equal(one.cells, two.cells)


def test_max_range_clears_nothing_by_default(grid) -> None:  # type: ignore[no-untyped-def]
    scan = build_scan([5.0, np.inf, 4.995], max_range=5.0)
    assert _free(scan, grid).count == 0
    m = AndersoneMapper(CFG, grid)
    m.integrate(scan)
    snap = m.snapshot()
    assert m.counters.cells_freed == 0 and not snap.observed.any()
    assert np.isnan(snap.probability).all()


def test_clear_on_max_range_clears_up_to_r_max(grid) -> None:  # type: ignore[no-untyped-def]
    cfg = MapperConfig(method="andersone", clear_on_max_range=True)
    for r in (5.0, np.inf):
        free = _free(build_scan([r], max_range=4.0, ox=-4.5, oy=0.0), grid, cfg)
        dist, _off, truth = _cone_truth(grid, -4.5, 0.0, 0.0, 4.0)
        got = np.zeros(grid.shape, dtype=bool)
        got.reshape(-1)[free.cells] = True
        assert np.array_equal(got, truth)
        assert dist[got].max() > 3.9
    m = AndersoneMapper(cfg, grid)
    m.integrate(build_scan([np.inf], max_range=4.0))
    assert m.snapshot().observed.sum() == m.counters.cells_freed > 0
    assert m.counters.features_created == 0


def test_cone_leaving_grid_is_clipped(grid) -> None:  # type: ignore[no-untyped-def]
    cfg = MapperConfig(method="andersone", feature_correction=False)
    m = AndersoneMapper(cfg, grid)
    m.integrate(build_scan([4.0, 4.0], alpha=[0.0, math.pi], ox=4.8, oy=4.8))
    snap = m.snapshot()
    t = m.feature_table()
    np.testing.assert_allclose(t.x, [8.8, 0.8])  # the first lies outside the grid, kept
    assert snap.occupied.any()
    xs, _ = cell_centres(grid)
    assert xs[snap.occupied].min() > 0.0  # only the in-grid feature is rasterised
    assert m.counters.cells_freed > 0


def test_ellipse_spans_match_mahalanobis(grid) -> None:  # type: ignore[no-untyped-def]
    mx, my = np.array([0.33, -1.0]), np.array([0.21, 2.0])
    cxx, cxy, cyy = np.array([0.09, 0.01]), np.array([0.05, 0.0]), np.array([0.04, 0.3])
    spans = ellipse_spans(mx, my, cxx, cxy, cyy, 2.0, grid)
    owner, row, col = span_cells(spans)
    x, y = cell_centres(grid)
    for k in range(2):
        dx, dy = x - mx[k], y - my[k]
        det = cxx[k] * cyy[k] - cxy[k] ** 2
        m2 = (cyy[k] * dx * dx - 2 * cxy[k] * dx * dy + cxx[k] * dy * dy) / det
        truth = m2 <= 4.0
        got = np.zeros(grid.shape, dtype=bool)
        got[row[owner == k], col[owner == k]] = True
        assert np.array_equal(got & ~(np.abs(m2 - 4) < 1e-9), truth & ~(np.abs(m2 - 4) < 1e-9))
        assert got.sum() > 20


def test_batched_free_space_scans_equal_the_per_scan_path() -> None:
    """free_space_scans over many scans at once (several windows batches, empty scans
    among them) gives each scan's free_space_scan, cell for cell."""
    cfg = MapperConfig(clear_on_max_range=True)
    grid = GridSpec(-12.0, -9.0, 0.02, 1200, 900)
    rng = np.random.default_rng(11)
    scans = []
    for k in range(40):
        n = int(rng.integers(1, 9))
        ranges = rng.uniform(0.3, 6.0, n)
        if k % 7 == 3:
            ranges[:] = np.nan  # a scan with no free space at all
        scans.append(
            build_scan(
                ranges, alpha=rng.uniform(-math.pi, math.pi, n),
                ox=rng.uniform(-13.0, 13.0), oy=rng.uniform(-10.0, 10.0),  # some off the grid
                t_ns=k,
            )
        )
    cat = Scan(*(np.concatenate([getattr(s, f) for s in scans]) for f in Scan.__dataclass_fields__))
    bounds = np.cumsum([0] + [len(s) for s in scans]).astype(np.int64)
    batched = free_space_scans(cat, bounds, classify_scan(cat, cfg), cfg, grid)
    assert len(batched) == len(scans)
    window_cells = 0
    for s, b in zip(scans, batched, strict=True):
        one = free_space_scan(s, classify_scan(s, cfg), cfg, grid)
        assert b.count == one.count
        assert b.cells.tolist() == one.cells.tolist()
        window_cells += b.mask.size
    assert window_cells > 1_000_000  # more than one batch of windows (1e6 cells)
    assert sum(b.count == 0 for b in batched) >= 5
