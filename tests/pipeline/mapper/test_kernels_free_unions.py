"""A group's packed free-space scans (kernels/free_unions.py) against the numpy reference:
the same cells for every scan (empty ones among them), the same free-layer counts; the free
cones counted from the same spans equal count_free's counts."""

from __future__ import annotations

import math

import numpy as np
from mapper_helpers import build_scan

from pipeline.config import MapperConfig
from pipeline.mapper.free_space import free_space_scans
from pipeline.mapper.kernels.attribution import count_free, empty_span_counts, span_counts
from pipeline.mapper.kernels.free_unions import NO_COUNTS, add_free_unions, free_unions, union_of
from pipeline.mapper.scan_group import ScanGroup
from pipeline.mapper.types import GridSpec, Scan


def _union_cells(u, k: int, width: int) -> list[int]:  # type: ignore[no-untyped-def]
    row0, col0, col1, starts, c0, c1, count = union_of(u, k)
    cells = [(row0 + r) * width + c for r in range(len(starts) - 1)
             for i in range(starts[r], starts[r + 1]) for c in range(c0[i], c1[i] + 1)]
    assert count == len(cells)
    if cells:
        assert col0 == min(c0.tolist()) and col1 == max(c1.tolist())
    return cells


def _group(seed: int) -> ScanGroup:
    """40 scans of 1-8 random readings (every seventh without free space) over GRID."""
    cfg = MapperConfig(clear_on_max_range=True)
    rng = np.random.default_rng(seed)
    scans: list[Scan] = []
    for k in range(40):
        n = int(rng.integers(1, 9))
        ranges = rng.uniform(0.3, 6.0, n)
        if k % 7 == 3:
            ranges[:] = np.nan  # a scan with no free space at all
        scans.append(build_scan(ranges, alpha=rng.uniform(-math.pi, math.pi, n),
                                ox=rng.uniform(-13.0, 13.0), oy=rng.uniform(-10.0, 10.0),
                                t_ns=k))
    return ScanGroup(scans, cfg)


GRID = GridSpec(-12.0, -9.0, 0.02, 1200, 900)  # fine: more rows than the first buffers


def test_packed_unions_equal_the_reference_free_space_scans() -> None:
    grid, group = GRID, _group(12)
    rows, cones, up_down = group.free_cones
    u = free_unions(cones, up_down, np.searchsorted(rows, group.bounds), grid.origin_x,
                    grid.origin_y, grid.resolution, grid.width, grid.height, NO_COUNTS)
    ref = free_space_scans(group.cat, group.bounds, group.codes, group.config, grid)
    assert u.head.shape[0] == len(ref) == 40
    assert u.row_cut[-1] > 1024 and u.span_cut[-1] > 1024  # the buffers grew
    want = np.zeros(grid.shape, dtype=np.int32)
    empty = 0
    for k, free in enumerate(ref):
        assert _union_cells(u, k, grid.width) == free.cells.tolist()
        want.reshape(-1)[free.cells] += 1
        empty += free.count == 0
    assert empty >= 5
    diff = np.zeros((grid.height, grid.width + 1), dtype=np.int32)
    add_free_unions(diff, u)
    assert diff[:, -1].min() < 0  # runs reaching the last column end in the extra one
    counts = np.cumsum(diff[:, :-1], axis=1)
    np.testing.assert_array_equal(counts, want)
    assert counts.max() >= 2  # overlapping scans counted once each


def test_free_cones_counted_from_the_unions_spans_equal_count_free() -> None:
    grid = GRID
    for seed in (12, 5):
        group = _group(seed)
        rows, cones, up_down = group.free_cones
        cut = np.searchsorted(rows, group.bounds)
        alone = free_unions(cones, up_down, cut, grid.origin_x, grid.origin_y, grid.resolution,
                            grid.width, grid.height, NO_COUNTS)
        shared = empty_span_counts(grid.shape)
        counted = free_unions(cones, up_down, cut, grid.origin_x, grid.origin_y,
                              grid.resolution, grid.width, grid.height, shared)
        for a, b in zip(alone, counted, strict=True):  # the unions themselves unchanged
            np.testing.assert_array_equal(a, b)
        want = empty_span_counts(grid.shape)
        cells = count_free(cones, up_down, grid.origin_x, grid.origin_y, grid.resolution, want)
        np.testing.assert_array_equal(shared, want)
        got = span_counts(shared)
        assert got.sum() == cells > 10_000
        assert got.max() >= 2  # overlapping cones counted once each
