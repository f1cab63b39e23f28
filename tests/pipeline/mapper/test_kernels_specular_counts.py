"""The count pass of the specular kernel (``trace_readings`` without ``attribute``) against
its rule written in numpy: each cone cell closer than ``r_free`` adds
``q·visible(θ) + (1 − q)·v̄`` to the free grid (float32, in reading order), each cell at or
beyond ``r_inner`` one arc. A reading that no surface stops takes the branch-free adds, one
whose stops are all infinite the per-cell loop: both give the rule's bits."""

from __future__ import annotations

import math

import numpy as np

from pipeline.mapper.free_space import cone_table
from pipeline.mapper.grid_raster import sector_spans
from pipeline.mapper.kernels.specular import shadow_offsets, trace_readings
from pipeline.mapper.synthetic import ring_scans, room_grid


def _rule(scan, rows, r_out, r_inner, r_free, half, grid, nx, ny, cons, table, v_unknown):  # type: ignore[no-untyped-def]
    free = np.zeros(grid.shape, np.float32)
    arcs = np.zeros(grid.shape, np.float32)
    n = table.shape[0]
    for i, k in enumerate(rows.tolist()):
        spans = sector_spans(scan.origin_x[k:k + 1], scan.origin_y[k:k + 1],
                             scan.alpha[k:k + 1], half[i:i + 1], r_out[k:k + 1], grid)
        for r, c0, c1 in zip(spans.row.tolist(), spans.c0.tolist(), spans.c1.tolist(),
                             strict=True):
            c = np.arange(c0, c1 + 1)
            dx = grid.origin_x + (c + 0.5) * grid.resolution - scan.origin_x[k]
            dy = grid.origin_y + (r + 0.5) * grid.resolution - scan.origin_y[k]
            d = np.sqrt(dx * dx + dy * dy)
            x = np.abs(dx * nx[r, c] + dy * ny[r, c]) / np.maximum(d, 1e-12) * (n - 1)
            kt = np.minimum(x.astype(np.int64), n - 2)
            f = x - kt
            q = cons[r, c].astype(np.float64)
            add = q * (table[kt] * (1.0 - f) + table[kt + 1] * f) + (1.0 - q) * v_unknown
            near = d < r_free[i]
            free[r, c[near]] = (free[r, c[near]].astype(np.float64) + add[near]).astype(np.float32)
            far = d >= r_inner[i]
            arcs[r, c[far]] += np.float32(1.0)
    return free, arcs


def test_the_count_pass_adds_the_rule_in_reading_order() -> None:
    grid = room_grid(0.1)
    scan = ring_scans(3)[1]
    rng = np.random.default_rng(7)
    r_out = np.where(scan.range_m < scan.max_range, scan.range_m + 0.2, scan.max_range)
    rows, cones, up_down = cone_table(scan, r_out)
    half = np.minimum(0.5 * scan.fov[rows], 0.5 * math.pi - 1e-9)
    r_inner = np.maximum(r_out[rows] - 0.4, 0.0)
    r_inner[::5] = np.inf  # readings with no echo: no arc
    r_free = r_out[rows] - 0.3
    psi = rng.uniform(-math.pi, math.pi, grid.shape)
    nx, ny = np.cos(psi).astype(np.float32), np.sin(psi).astype(np.float32)
    cons = rng.uniform(0.0, 1.0, grid.shape).astype(np.float32)
    table = np.linspace(0.1, 0.9, 33) ** 2
    offsets = shadow_offsets(cones, half, grid.resolution)
    stops = np.full(int(offsets[-1]), np.inf)
    want = _rule(scan, rows, r_out, r_inner, r_free, half, grid, nx, ny, cons, table, 0.37)
    assert want[0].max() > 1.0 and want[1].sum() > 50
    stopped = np.zeros(len(rows), dtype=bool)
    for path in ("branch-free adds", "per-cell loop"):
        free = np.zeros(grid.shape, np.float32)
        arcs = np.zeros(grid.shape, np.float32)
        lost = trace_readings(
            cones, up_down, r_inner, r_free, scan.alpha[rows], half, grid.origin_x,
            grid.origin_y, grid.resolution, offsets, stops, stopped, nx, ny, cons, table, 0.37,
            False, False, free, arcs, 1.0, 1.0, free, arcs, np.zeros_like(free),
            np.zeros_like(free), np.zeros_like(free), 0, grid.shape[0],
        )
        assert lost == 0
        assert np.array_equal(free, want[0]), path
        assert np.array_equal(arcs, want[1]), path
        stopped[:] = True  # every reading stopped nowhere: the per-cell loop
