"""§9 echo attribution: the cone kernels' cells, the attribution rule, the two-pass mapper."""

from __future__ import annotations

import numpy as np
import pytest
from mapper_helpers import build_scan, cell_centres

from pipeline.config import MapperConfig
from pipeline.mapper import AttributionMapper, make_mapper
from pipeline.mapper.grid_raster import cone_edges, sector_spans, span_cells
from pipeline.mapper.kernels.attribution import (
    attribute_echoes,
    count_arcs,
    count_free,
    empty_grid,
    empty_span_counts,
    span_counts,
)
from pipeline.mapper.synthetic import ring_scans, room_grid, room_segments
from pipeline.mapper.types import GridSpec

GRID = GridSpec(-5.0, -5.0, 0.05, 200, 200)
CFG = MapperConfig(method="attribution")  # §9


def _table(ox, oy, alpha, hf, r_outer):  # type: ignore[no-untyped-def]
    """Cones as the kernels take them (free_space.cone_table's columns)."""
    s1, c1, s2, c2, up, down = cone_edges(np.asarray(alpha), np.asarray(hf))
    cones = np.stack([ox, oy, r_outer, s1, c1, s2, c2], axis=1).astype(np.float64)
    return cones, np.stack([up, down], axis=1)


def _counts(fill, *args) -> np.ndarray:  # type: ignore[no-untyped-def]
    diff = empty_span_counts(GRID.shape)
    fill(*args, GRID.origin_x, GRID.origin_y, 0.05, diff)
    return span_counts(diff)


def _in_cone(grid: GridSpec, ox: float, oy: float, a: float, hf: float) -> tuple:
    x, y = cell_centres(grid)
    dx, dy = x - ox, y - oy
    dist = np.hypot(dx, dy)
    inside = dx * np.cos(a) + dy * np.sin(a) >= dist * np.cos(hf)
    return dist, inside


def test_free_cone_counts_are_the_span_rasteriser_cells() -> None:
    rng = np.random.default_rng(3)
    n = 40
    ox, oy = rng.uniform(-3, 3, n), rng.uniform(-3, 3, n)
    alpha, hf = rng.uniform(-np.pi, np.pi, n), rng.uniform(0.05, 0.6, n)
    radius = rng.uniform(0.2, 4.0, n)
    diff = empty_span_counts(GRID.shape)
    added = count_free(*_table(ox, oy, alpha, hf, radius), GRID.origin_x, GRID.origin_y, 0.05,
                       diff)
    counts = span_counts(diff)
    ref = np.zeros(GRID.shape, dtype=np.float32)
    _, row, col = span_cells(sector_spans(ox, oy, alpha, hf, radius, GRID))
    np.add.at(ref, (row, col), 1.0)
    # One rasteriser: the andersone mapper's cones, cell for cell.
    assert added == int(ref.sum()) > 1000
    np.testing.assert_array_equal(counts, ref)


def test_arc_cells_are_the_band_around_the_echo_inside_the_cone() -> None:
    one = np.array([1.0])
    counts = _counts(count_arcs, *_table(0.1 * one, 0.2 * one, 0.3 * one, 0.25 * one, 2.1 * one),
                     1.9 * one)
    dist, inside = _in_cone(GRID, 0.1, 0.2, 0.3, 0.25)
    expected = inside & (np.abs(dist - 2.0) <= 0.1 + 1e-12)
    assert np.array_equal(counts > 0, expected)
    assert counts.max() == 1.0 and expected.sum() > 20


@pytest.mark.parametrize("alpha", [0.5 * np.pi, -0.5 * np.pi])
def test_an_arc_counts_each_cell_once_where_its_inner_chord_is_narrow(alpha: float) -> None:
    # Cell centres lie on y = ±(0.025 + k·0.05): the row at |y| = 1.025 crosses the inner
    # circle (radius 1.025 + 1e-5) in a chord 9 mm wide, narrower than a cell; the cells
    # either side of it are in the arc once (the rasteriser before the unification counted
    # them twice, once per half of the row).
    one = np.array([1.0])
    r_in, r_out = 1.025 + 1e-5, 1.2
    counts = _counts(count_arcs, *_table(0 * one, 0 * one, alpha * one, 0.5 * one, r_out * one),
                     r_in * one)
    dist, inside = _in_cone(GRID, 0.0, 0.0, alpha, 0.5)
    truth = inside & (dist >= r_in) & (dist <= r_out)
    assert counts.max() == 1.0
    np.testing.assert_array_equal(counts > 0, truth)
    row = round(float(np.sign(alpha)) * 1.025 / 0.05 + 99.5)
    assert counts[row, 99] == counts[row, 100] == 1.0  # x = ∓0.025, just outside the chord


def _arc_of(d: float) -> tuple:
    zero, band = np.array([0.0]), 0.05
    cones, up_down = _table(zero, zero, zero, np.array([0.2]), np.array([d + band]))
    return cones, up_down, np.array([d - band])


def _arcs(arc: tuple) -> np.ndarray:
    return _counts(count_arcs, *arc)


def test_an_echo_is_spread_over_its_candidates_by_the_dilution_law() -> None:
    arc = _arc_of(2.0)
    free, hits = empty_grid(GRID.shape), empty_grid(GRID.shape)
    arcs = _arcs(arc)
    n = int(np.count_nonzero(arcs))
    lost = attribute_echoes(*arc, GRID.origin_x, GRID.origin_y, 0.05, free, arcs, 2.0, 0.5, hits)
    assert lost == 0
    assert np.allclose(hits[arcs > 0], 1.0 / np.sqrt(n))
    assert np.count_nonzero(hits) == n
    even = empty_grid(GRID.shape)
    attribute_echoes(*arc, GRID.origin_x, GRID.origin_y, 0.05, free, arcs, 2.0, 1.0, even)
    assert even.sum() == pytest.approx(1.0, rel=1e-5)  # dilution 1: an even split


def test_arc_cells_seen_free_cannot_have_produced_the_echo() -> None:
    arc = _arc_of(2.0)
    free, hits = empty_grid(GRID.shape), empty_grid(GRID.shape)
    arcs = _arcs(arc)
    rows, cols = np.nonzero(arcs)
    # Every arc cell but one was seen free 3 times, more than 2 × its one arc.
    free[rows[1:], cols[1:]] = 3.0
    lost = attribute_echoes(*arc, GRID.origin_x, GRID.origin_y, 0.05, free, arcs, 2.0, 0.5, hits)
    assert lost == 0 and hits[rows[0], cols[0]] == 1.0 and np.count_nonzero(hits) == 1
    free[rows[0], cols[0]] = 3.0  # now the whole arc is known free: the echo is unexplained
    hits[:] = 0
    lost = attribute_echoes(*arc, GRID.origin_x, GRID.origin_y, 0.05, free, arcs, 2.0, 0.5, hits)
    assert lost == 1 and not hits.any()


def _room_map(cfg: MapperConfig, n_scans: int = 400):  # type: ignore[no-untyped-def]
    scans = ring_scans(n_scans, seed=2)
    m = make_mapper(cfg, room_grid())
    for index in range(m.passes):
        m.begin_pass(index)
        m.integrate_many(scans)
    return m, m.snapshot()


def _wall_distance(grid: GridSpec) -> np.ndarray:
    """Distance of every cell centre to the room's nearest wall segment, m."""
    x, y = cell_centres(grid)
    best = np.full(grid.shape, np.inf)
    for x0, y0, x1, y1 in room_segments():
        ex, ey = x1 - x0, y1 - y0
        t = np.clip(((x - x0) * ex + (y - y0) * ey) / (ex * ex + ey * ey), 0.0, 1.0)
        best = np.minimum(best, np.hypot(x - (x0 + t * ex), y - (y0 + t * ey)))
    return best


def test_the_room_map_puts_occupied_cells_on_the_walls() -> None:
    m, snap = _room_map(CFG)
    assert isinstance(m, AttributionMapper)
    near = _wall_distance(snap.grid)
    occupied = snap.occupied
    precision = float((near[occupied] <= 0.10).mean())
    assert occupied.sum() > 1000 and precision > 0.85
    # The paper's features ride along for features.parquet and its metric.
    assert len(snap.features) > 50 and np.isfinite(m.feature_variance()[0])
    # Free cells are free (far from walls) and carry the free layer's probability.
    free = snap.probability < 0.196
    assert free.sum() > 5000 and float((near[free] > 0.10).mean()) > 0.99
    assert np.all(snap.probability[occupied] == np.float32(CFG.p_occ))


def test_the_attribution_map_beats_the_classic_grid_on_the_room() -> None:
    _, ours = _room_map(CFG)
    _, classic = _room_map(MapperConfig(method="classic"))
    near = _wall_distance(ours.grid)

    def precision(occ: np.ndarray) -> float:
        return float((near[occ] <= 0.10).mean())

    assert precision(ours.occupied) > precision(classic.occupied) + 0.2  # 0.90 vs 0.60


def test_two_runs_give_the_same_map_and_passes_are_checked() -> None:
    _, a = _room_map(CFG, 40)
    _, b = _room_map(CFG, 40)
    assert np.array_equal(a.probability, b.probability, equal_nan=True)
    with pytest.raises(ValueError, match="passes 0 and 1"):
        AttributionMapper(CFG, room_grid()).begin_pass(2)


def test_counters_count_readings_once_and_unexplained_echoes() -> None:
    m = make_mapper(CFG, GRID)
    scan = build_scan([2.0, 5.0, np.nan])
    for index in range(m.passes):
        m.begin_pass(index)
        m.integrate(scan)
    c = m.counters
    assert (c.readings, c.readings_used, c.skipped_max_range, c.skipped_nan) == (3, 1, 1, 1)
    assert c.echoes_unattributed == 0
    snap = m.snapshot()
    assert snap.occupied.any()  # one echo, nothing contradicts it: its arc is occupied


def test_cells_no_cone_reached_stay_unknown() -> None:
    m = make_mapper(CFG, GRID)
    scan = build_scan([2.0])  # one echo 2 m along +x from the origin, 30° beam
    for index in range(m.passes):
        m.begin_pass(index)
        m.integrate(scan)
    snap = m.snapshot()
    x, _ = cell_centres(GRID)
    behind = x < -0.5  # behind the sonar: no cone reaches these cells
    assert np.isnan(snap.probability[behind]).all() and not snap.observed[behind].any()
    seen = snap.observed & ~snap.occupied
    assert seen.any() and (snap.probability[seen] < 0.5).all()  # the cone before the echo
    assert int(snap.observed.sum()) < GRID.width * GRID.height // 20
