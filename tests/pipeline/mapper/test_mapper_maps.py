"""§5 layers and eq. 12, determinism, the classic baseline (§8), the synthetic room (§7)."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mapper_helpers import build_scan, cell_centres

from formats.errors import ConfigError
from formats.map_types import GridSpec
from pipeline.config import MapperConfig
from pipeline.mapper import AndersoneMapper, AttributionMapper, ClassicMapper, make_mapper
from pipeline.mapper.occupancy import FreeLayer, logit, occupied_layer
from pipeline.mapper.synthetic import ring_scans, room_grid

CFG = MapperConfig(method="andersone")
ROOT = Path(__file__).resolve().parents[3]


def test_free_layer_update_and_clamp() -> None:
    layer = FreeLayer(GridSpec(0, 0, 1.0, 3, 1), 0.35, 0.12, 0.97)
    ref = 0.0
    for i in range(12):
        layer.update(np.array([1]))
        ref = min(max(ref + logit(0.35), logit(0.12)), logit(0.97))
        assert layer.logodds[0, 1] == pytest.approx(ref, abs=1e-6)
        if i == 0:
            assert layer.logodds[0, 1] == np.float32(logit(0.35))
    assert layer.logodds[0, 1] == np.float32(logit(0.12))  # clamped: stays revisable
    assert layer.logodds[0, 0] == 0 and layer.observed.tolist() == [[False, True, False]]


def test_free_layer_row_runs_sum_in_when_counts_are_read() -> None:
    layer = FreeLayer(GridSpec(0, 0, 1.0, 4, 2), 0.35, 0.12, 0.97)
    layer.update(np.array([0, 5]))
    diff = layer.diff_for_rows()
    diff[0, 1] += 1  # row 0, columns 1..3 (past the last: the extra column)
    diff[0, 4] -= 1
    diff[1, 0] += 2  # row 1, columns 0..1, twice
    diff[1, 2] -= 2
    assert layer.counts.tolist() == [[1, 1, 1, 1], [2, 3, 0, 0]]
    assert not layer.row_diff.any()  # summed in once
    assert layer.counts.tolist() == [[1, 1, 1, 1], [2, 3, 0, 0]]
    assert layer.logodds[1, 1] == np.float32(logit(0.35)) * 3  # three updates, unclamped
    assert layer.observed[1].tolist() == [True, True, False, False]


def test_unknown_is_nan_and_free_probability(grid) -> None:  # type: ignore[no-untyped-def]
    m = AndersoneMapper(MapperConfig(method="andersone", feature_correction=False), grid)
    snap = m.snapshot()
    assert np.isnan(snap.probability).all() and not snap.observed.any()
    assert snap.probability.dtype == np.float32 and snap.probability.shape == grid.shape
    m.integrate(build_scan([3.0]))
    snap = m.snapshot()
    x, y = cell_centres(grid)
    free_cell = (np.abs(x - 1.025) < 1e-9) & (np.abs(y - 0.025) < 1e-9)
    assert snap.probability[free_cell][0] == pytest.approx(0.35, abs=1e-6)
    behind = (np.abs(x - 4.025) < 1e-9) & (np.abs(y - 0.025) < 1e-9)
    assert np.isnan(snap.probability[behind][0])
    assert snap.observed.sum() == m.counters.cells_freed + np.count_nonzero(
        snap.occupied & (snap.free_logodds == 0)
    )


def test_feature_ellipse_overrides_free_log_odds(grid) -> None:  # type: ignore[no-untyped-def]
    m = AndersoneMapper(MapperConfig(method="andersone", feature_correction=False), grid)
    for _ in range(10):  # drive the cells in front of the origin to the lower clamp
        m.integrate(build_scan([4.0], ox=-2.0))
    # A feature right inside that free region (as if put there by another sensor).
    m.features.add(np.array([[0.0, 0.0]]), np.array([[0.01, 0.0, 0.01]]), np.array([0]))
    snap = m.snapshot()
    r, c = 100, 100  # the cell whose corner is (0, 0)
    assert snap.free_logodds[r, c] == np.float32(logit(0.12))
    assert snap.occupied[r, c] and snap.probability[r, c] == np.float32(0.9)
    # 2σ ellipse = 0.2 m radius: the cell 0.225 m away is outside and keeps its free value.
    assert not snap.occupied[r, c + 4]
    assert snap.probability[r, c + 4] == pytest.approx(0.12, abs=1e-6)


def test_tiny_ellipse_marks_its_mean_cell(grid) -> None:  # type: ignore[no-untyped-def]
    m = AndersoneMapper(CFG, grid)
    m.features.add(np.array([[0.01, 0.02]]), np.array([[1e-8, 0.0, 1e-8]]), np.array([0]))
    snap = m.snapshot()
    assert np.argwhere(snap.occupied).tolist() == [[100, 100]]


def _run(cfg: MapperConfig, n: int = 60):  # type: ignore[no-untyped-def]
    m = make_mapper(cfg, room_grid())
    for s in ring_scans(n):
        m.integrate(s)
    return m


def test_same_seed_same_state_other_seed_differs() -> None:
    a, b, c = _run(CFG), _run(CFG), _run(MapperConfig(method="andersone", seed=1))
    ta, tb, tc = a.feature_table(), b.feature_table(), c.feature_table()
    for col in ("id", "x", "y", "cov_xx", "cov_xy", "cov_yy", "measured_times"):
        np.testing.assert_array_equal(getattr(ta, col), getattr(tb, col))
    sa, sb = a.snapshot(), b.snapshot()
    assert sa.probability.tobytes() == sb.probability.tobytes()
    assert sa.counters == sb.counters
    assert len(ta) != len(tc) or not np.array_equal(ta.x, tc.x)


def test_classic_marks_obstacle_occupied_and_cone_free(grid) -> None:  # type: ignore[no-untyped-def]
    literal = MapperConfig(method="classic", classic_per_reading=False, classic_thickness_cells=2)
    m = make_mapper(literal, grid)
    assert isinstance(m, ClassicMapper)
    for _ in range(3):
        m.integrate(build_scan([2.0, 5.0], alpha=[0.0, math.pi / 2]))
    snap = m.snapshot()
    x, y = cell_centres(grid)
    at = lambda px, py: (np.abs(x - px) < 1e-9) & (np.abs(y - py) < 1e-9)  # noqa: E731
    p_occ = 1 - 1 / (1 + math.exp(min(3 * logit(0.7), logit(0.97))))
    assert snap.probability[at(2.025, 0.025)][0] == pytest.approx(p_occ, abs=1e-6)
    assert snap.occupied[at(2.025, 0.025)][0]
    assert snap.probability[at(1.025, 0.025)][0] == pytest.approx(1 / (1 + math.exp(-3 * logit(0.35))), abs=1e-6)
    assert not snap.occupied[at(1.025, 0.025)][0]
    assert np.isnan(snap.probability[at(2.525, 0.025)][0])  # behind the obstacle
    assert np.isnan(snap.probability[at(0.025, 1.025)][0])  # max-range reading ignored
    assert len(m.feature_table()) == 0 and all(math.isnan(v) for v in m.feature_variance())
    assert (m.counters.readings, m.counters.skipped_max_range, m.counters.readings_used) == (6, 3, 3)


def test_make_mapper_rejects_unknown_method(grid) -> None:  # type: ignore[no-untyped-def]
    assert isinstance(make_mapper(CFG, grid), AndersoneMapper)
    assert isinstance(make_mapper(MapperConfig(), grid), AttributionMapper)
    with pytest.raises(ConfigError, match=r"mapper\.method"):
        make_mapper(MapperConfig(method="nope"), grid)  # type: ignore[arg-type]


def _room_variance(scans, **kw):  # type: ignore[no-untyped-def]
    var = {}
    for on in (True, False):
        m = make_mapper(MapperConfig(method="andersone", feature_correction=on, **kw), room_grid())
        for s in scans:
            m.integrate(s)
        var[on] = m.feature_variance()
        snap = m.snapshot()
        assert snap.occupied.any() and np.nanmax(snap.probability) == np.float32(0.9)
    return var


def test_room_correction_lowers_mean_feature_variance() -> None:
    """The paper's §4 result on a synthetic room (16-sonar ring, 2 m sonars), defaults."""
    var = _room_variance(ring_scans(250, max_range=2.0))
    assert var[True][0] < 0.95 * var[False][0]
    assert var[True][1] < var[False][1]


def test_split_guard_keeps_long_range_refits_from_growing() -> None:
    """With 5 m sonars, free cones cut wide features in two; the split guard clears those
    instead of refitting across the cone, and the variance stays below the uncorrected one."""
    var = _room_variance(ring_scans(250, max_range=5.0), split_guard=True)
    assert var[True][0] < 0.95 * var[False][0]


def test_cell_centre_refits_accumulate_rounding_variance() -> None:
    """Why refit_positions defaults to 'particle': with cell centres, every refit adds
    ~res²/12 per axis, and the paper's result no longer holds on the same room."""
    scans = ring_scans(250, max_range=2.0)
    particle = _room_variance(scans)[True][0]
    cell = _room_variance(scans, refit_positions="cell")[True][0]
    assert cell > 1.2 * particle


def test_benchmark_smoke() -> None:
    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_mapper.py"), "--smoke"],
        capture_output=True, text=True, timeout=120, check=True,
    ).stdout
    for name in ("andersone+correction", "andersone", "classic"):
        assert f"{name} " in out
    assert "readings/s" in out


def test_classic_one_scan_frees_only_before_the_echo_and_counts_it(grid) -> None:  # type: ignore[no-untyped-def]
    """Every touched cell of one echo: free strictly before d − w/2, occupied within w/2
    of d, nothing beyond; counters and snapshot fields agree with the cells."""
    cfg = MapperConfig(method="classic")
    m = make_mapper(cfg, grid)
    d, alpha, ox, oy = 2.0, 0.3, 0.4, -0.7
    m.integrate(build_scan([d, 7.0, math.nan], alpha=alpha, ox=ox, oy=oy))  # + max range, NaN
    snap = m.snapshot()
    x, y = cell_centres(grid)
    dist = np.hypot(x - ox, y - oy)
    half_w = 0.5 * cfg.classic_thickness_cells * grid.resolution
    touched = ~np.isnan(snap.probability)
    free = touched & (snap.probability < 0.5)
    occ = touched & (snap.probability > 0.5)
    assert free.sum() > 100 and occ.sum() > 5
    assert (dist[free] < d - half_w).all()
    assert (np.abs(dist[occ] - d) <= half_w + 1e-9).all()
    assert not (touched & (dist > d + half_w + 1e-9)).any()  # nothing behind the echo
    bearing = np.arctan2(y - oy, x - ox) - alpha
    off_axis = np.abs((bearing + np.pi) % (2 * np.pi) - np.pi)
    assert (off_axis[touched] <= np.radians(15.0) + grid.resolution / d).all()
    assert np.array_equal(snap.observed, touched) and np.array_equal(snap.occupied, occ)
    assert np.array_equal(snap.free_logodds != 0, touched)
    assert snap.probability[free].max() == pytest.approx(0.35, abs=1e-6)  # one free update
    assert snap.probability[occ].min() == pytest.approx(0.7, abs=1e-6)  # one occupied update
    assert len(snap.features) == 0
    assert snap.counters == m.counters.as_dict()
    c = snap.counters
    assert (c["scans"], c["readings"], c["readings_used"]) == (1, 3, 1)
    assert (c["skipped_max_range"], c["skipped_nan"], c["features_created"]) == (1, 1, 0)
    assert c["cells_freed"] == int(free.sum())


def test_occupied_layer_matches_mahalanobis_over_several_raster_blocks() -> None:
    """More features than one raster block, none at the origin, x ≠ y: the occupied cells
    are exactly the cell centres within 2σ of some feature, plus each mean's cell."""
    grid = GridSpec(-1.3, 0.7, 0.1, 60, 40)  # x in [-1.3, 4.7), y in [0.7, 4.7)
    rng = np.random.default_rng(5)
    n = 2600  # > 2048 features rasterised at once
    mean = np.column_stack([rng.uniform(-1.5, 4.9, n), rng.uniform(0.5, 4.9, n)])
    sx, sy = rng.uniform(0.01, 0.12, n), rng.uniform(0.01, 0.12, n)
    rho = rng.uniform(-0.9, 0.9, n)
    cov = np.column_stack([sx**2, rho * sx * sy, sy**2])
    got = occupied_layer(mean, cov, grid)
    x, y = cell_centres(grid)
    want = np.zeros(grid.shape, dtype=bool)
    unsure = np.zeros(grid.shape, dtype=bool)
    for (mx, my), (a, b, c) in zip(mean, cov, strict=True):
        dx, dy = x - mx, y - my
        d2 = (c * dx * dx - 2 * b * dx * dy + a * dy * dy) / (a * c - b * b)
        want |= d2 <= 4.0
        unsure |= np.abs(d2 - 4.0) < 1e-6
        col, row = math.floor((mx + 1.3) / 0.1), math.floor((my - 0.7) / 0.1)
        if 0 <= col < 60 and 0 <= row < 40:
            want[row, col] = True
    assert 200 < want.sum() < want.size  # a meaningful, not saturated, layer
    assert np.array_equal(got[~unsure], want[~unsure])


@pytest.mark.parametrize("reference", [False, True], ids=["kernel", "reference"])
def test_classic_per_reading_updates_a_cell_once_per_reading(grid, reference) -> None:  # type: ignore[no-untyped-def]
    x, y = cell_centres(grid)
    free_cell = (np.abs(x - 1.025) < 1e-9) & (np.abs(y - 0.025) < 1e-9)
    echo_cell = (np.abs(x - 2.025) < 1e-9) & (np.abs(y - 0.025) < 1e-9)
    values = {}
    for per_reading in (True, False):
        cfg = MapperConfig(method="classic", classic_per_reading=per_reading)
        m = ClassicMapper(cfg, grid, reference=reference)
        m.integrate(build_scan([2.025, 2.025, 2.025]))  # three readings of one cone, one scan
        values[per_reading] = (m.logodds[free_cell][0], m.logodds[echo_cell][0], m.counters.scans)
    assert values[True][0] == pytest.approx(3 * logit(0.35), abs=1e-5)  # three free updates
    assert values[True][1] == pytest.approx(min(3 * logit(0.7), logit(0.97)), abs=1e-5)
    assert values[False][0] == pytest.approx(logit(0.35), abs=1e-6)  # one per scan
    assert values[True][2] == values[False][2] == 1
