"""Eqs. 1-8: reading features, classification, Kalman merge, nearest-neighbour matching."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from formats.map_types import GridSpec
from pipeline.config import MapperConfig
from pipeline.mapper import AndersoneMapper
from pipeline.mapper.features_reference import FeatureSet, feature_variance, kalman_merge
from pipeline.mapper.reading_features import (
    beam_covariance,
    classify_scan,
    distance_sigma,
    lateral_sigma,
    reading_features,
)

CFG = MapperConfig(method="andersone")
BETA = math.radians(30.0)


def test_sigmas_at_known_ranges() -> None:
    assert distance_sigma(2.0, CFG) == pytest.approx(0.01 + 0.01 * 2.0)
    assert lateral_sigma(2.0, BETA, CFG) == pytest.approx(2.0 * math.tan(BETA / 2) / 2.0)
    # c_a = 2 puts the 2σ lateral bound on the cone edge.
    assert 2 * lateral_sigma(3.0, BETA, CFG) == pytest.approx(3.0 * math.tan(BETA / 2))


def test_covariance_axis_aligned_at_zero_and_rotated() -> None:
    sd, sa = 0.03, 2.0 * math.tan(BETA / 2) / 2.0
    p0 = beam_covariance([2.0], [0.0], [BETA], CFG)[0]
    np.testing.assert_allclose(p0, [sd**2, 0.0, sa**2], atol=1e-15)
    p90 = beam_covariance([2.0], [math.pi / 2], [BETA], CFG)[0]
    np.testing.assert_allclose(p90, [sa**2, 0.0, sd**2], atol=1e-15)
    a = 0.7
    r = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    want = r @ np.diag([sd**2, sa**2]) @ r.T
    p = beam_covariance([2.0], [a], [BETA], CFG)[0]
    np.testing.assert_allclose(p, [want[0, 0], want[0, 1], want[1, 1]], rtol=1e-12)


def test_feature_mean_on_beam_axis(make_scan) -> None:  # type: ignore[no-untyped-def]
    scan = make_scan([2.0, 1.0], alpha=[0.0, math.pi / 2], ox=[1.0, -1.0], oy=[0.5, 0.0])
    feats = reading_features(scan, classify_scan(scan, CFG), CFG)
    np.testing.assert_allclose(feats.mean, [[3.0, 0.5], [-1.0, 1.0]], atol=1e-12)
    assert feats.row.tolist() == [0, 1]


def test_skipped_readings_counted_by_reason(make_scan, grid) -> None:  # type: ignore[no-untyped-def]
    ranges = [np.nan, np.inf, -np.inf, -1.0, 0.05, 4.995, 5.0, 2.0]
    # Without correction the one feature stays where eq. 1 put it.
    m = AndersoneMapper(MapperConfig(method="andersone", feature_correction=False), grid)
    m.integrate(make_scan(ranges, min_range=0.1, max_range=5.0))
    c = m.counters
    assert (c.readings, c.readings_used, c.features_created) == (8, 1, 1)
    assert (c.skipped_nan, c.skipped_pos_inf, c.skipped_neg_inf) == (1, 1, 1)
    assert (c.skipped_negative, c.skipped_below_min, c.skipped_max_range) == (1, 1, 2)
    t = m.feature_table()
    assert t.x.tolist() == pytest.approx([2.0]) and t.measured_times.tolist() == [1]


def test_non_finite_geometry_is_skipped_as_nan(make_scan, grid) -> None:  # type: ignore[no-untyped-def]
    m = AndersoneMapper(CFG, grid)
    m.integrate(make_scan([1.0, 1.0], ox=[np.nan, 0.0]))
    assert (m.counters.skipped_nan, m.counters.features_created) == (1, 1)


@st.composite
def spd(draw: st.DrawFn) -> np.ndarray:
    a = draw(st.floats(-2.0, 2.0))
    s1 = draw(st.floats(0.01, 1.0))
    s2 = draw(st.floats(0.01, 1.0))
    r = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    return r @ np.diag([s1**2, s2**2]) @ r.T


def _cols(p: np.ndarray) -> np.ndarray:
    return np.array([[p[0, 0], p[0, 1], p[1, 1]]])


@settings(max_examples=200, deadline=None)
@given(
    spd(),
    spd(),
    st.tuples(st.floats(-1, 1), st.floats(-1, 1)),
    st.tuples(st.floats(-1, 1), st.floats(-1, 1)),
)
def test_kalman_merge_is_information_fusion_and_shrinks(
    pf: np.ndarray, pz: np.ndarray, mf: tuple[float, float], mz: tuple[float, float]
) -> None:
    mu, p = kalman_merge(np.array([mf]), _cols(pf), np.array([mz]), _cols(pz))
    info = np.linalg.inv(pf) + np.linalg.inv(pz)
    p_want = np.linalg.inv(info)
    mu_want = p_want @ (np.linalg.inv(pf) @ np.array(mf) + np.linalg.inv(pz) @ np.array(mz))
    np.testing.assert_allclose(mu[0], mu_want, atol=1e-9)
    np.testing.assert_allclose(p[0], _cols(p_want)[0], atol=1e-9, rtol=1e-7)
    merged = np.array([[p[0, 0], p[0, 1]], [p[0, 1], p[0, 2]]])
    for prior in (pf, pz):  # Loewner order: prior − merged is positive semi-definite
        assert np.linalg.eigvalsh(prior - merged).min() >= -1e-10


def _set(md: float = 0.15) -> FeatureSet:
    return FeatureSet(GridSpec(-5.0, -5.0, 0.05, 200, 200), md)


def _cov(n: int) -> np.ndarray:
    return np.tile([0.01, 0.0, 0.01], (n, 1))


def test_reading_merges_into_nearest_within_match_distance() -> None:
    fs = _set()
    fs.add(np.array([[1.0, 0.0], [1.2, 0.0]]), _cov(2), np.array([1, 1]))
    created, merged = fs.merge_readings(np.array([[1.13, 0.0]]), _cov(1), np.array([5]))
    assert (created, merged) == (0, 1)
    t = fs.table()
    assert t.merges.tolist() == [0, 1] and t.measured_times.tolist() == [1, 2]
    assert t.last_seen_ns.tolist() == [1, 5]
    assert t.x[1] == pytest.approx(0.5 * (1.2 + 1.13))  # equal covariances: midpoint
    assert t.x[0] == 1.0


def test_reading_beyond_match_distance_creates_feature() -> None:
    fs = _set()
    fs.add(np.array([[1.0, 0.0]]), _cov(1), np.array([1]))
    created, merged = fs.merge_readings(np.array([[1.0, 0.16]]), _cov(1), np.array([2]))
    assert (created, merged) == (1, 0)
    assert fs.table().id.tolist() == [0, 1]


def test_merges_within_a_scan_are_sequential() -> None:
    """Reading 1 merges into the feature reading 0 created, reading 2 into the merged one
    (0.15 m from reading 0, but 0.10 m from the merged mean)."""
    fs = _set()
    pts = np.array([[0.0, 0.0], [0.1, 0.0], [0.15, 0.0], [3.0, 3.0]])
    created, merged = fs.merge_readings(pts, _cov(4), np.arange(4))
    assert (created, merged) == (2, 2)
    t = fs.table()
    assert t.measured_times.tolist() == [3, 1]
    # Sequential means with equal covariances: weights 1/3 each after two merges.
    assert t.x[0] == pytest.approx(0.25 / 3)
    # The same as one reading at a time.
    fs2 = _set()
    for i in range(4):
        fs2.merge_readings(pts[i : i + 1], _cov(1), np.array([i]))
    np.testing.assert_array_equal(fs2.table().x, t.x)
    np.testing.assert_array_equal(fs2.table().cov_xx, t.cov_xx)


def test_nearest_matches_brute_force_and_index_survives_moves() -> None:
    rng = np.random.default_rng(3)
    fs = _set(md=0.3)
    fs.add(rng.uniform(-6, 6, (3000, 2)), _cov(3000), np.zeros(3000, dtype=np.int64))
    fs.delete(np.arange(0, 3000, 3))
    moved = np.arange(1, 3000, 3)
    fs.move(moved, fs.mean[moved] + rng.normal(0, 0.5, (moved.size, 2)), _cov(moved.size))
    q = rng.uniform(-6, 6, (500, 2))
    slot, dist = fs.nearest(q)
    alive = fs.alive_slots()
    d_all = np.hypot(fs.mean[alive, 0][None] - q[:, 0:1], fs.mean[alive, 1][None] - q[:, 1:2])
    best = d_all.min(axis=1)
    near = best < 0.3  # the index promises exactness within reach of the 3×3 buckets
    np.testing.assert_allclose(dist[near], best[near])
    assert np.array_equal(alive[d_all.argmin(axis=1)][near], slot[near])
    assert len(fs) == 2000


def test_compaction_keeps_ids_sorted_and_index_valid() -> None:
    fs = _set()
    pts = np.stack([np.linspace(-4, 4, 4000), np.zeros(4000)], axis=1)
    fs.add(pts, _cov(4000), np.zeros(4000, dtype=np.int64))
    fs.delete(np.arange(0, 4000, 2))
    assert fs.n == 2000  # compacted
    t = fs.table()
    assert np.all(np.diff(t.id) > 0) and t.id[0] == 1
    slot, dist = fs.nearest(pts[1:2])
    assert dist[0] == 0.0 and fs.ids[slot[0]] == 1


def test_feature_variance_definition() -> None:
    cov = np.array([[4.0, 0.0, 1.0], [1.0, 0.0, 1.0]])
    assert feature_variance(cov) == pytest.approx((1.75, 2.5))
    assert all(math.isnan(v) for v in feature_variance(np.zeros((0, 3))))


def _reference_merge(feats: list[list], pts: np.ndarray, cov: np.ndarray, t: np.ndarray, md: float) -> None:
    """§2 one reading at a time, brute-force nearest (ties → oldest feature)."""
    for i in range(pts.shape[0]):
        best, best_d = -1, np.inf
        for j, f in enumerate(feats):
            d = float(np.hypot(f[0][0] - pts[i, 0], f[0][1] - pts[i, 1]))
            if d < best_d:
                best, best_d = j, d
        if best >= 0 and best_d < md:
            f = feats[best]
            mu, p = kalman_merge(f[0][None], f[1][None], pts[i : i + 1], cov[i : i + 1])
            f[0], f[1] = mu[0], p[0]
            f[2] += 1  # measured
            f[3] += 1  # merges
            f[5] = int(t[i])  # last seen
        else:
            feats.append([pts[i].copy(), cov[i].copy(), 1, 0, int(t[i]), int(t[i])])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_block_merge_equals_one_reading_at_a_time(seed: int) -> None:
    """Dense readings (chains into one feature, merges into features created in the same
    scan, a scan longer than the 512 readings merged at once) give exactly the sequential
    result."""
    rng = np.random.default_rng(seed)
    md = 0.15
    fs = _set(md)
    ref: list[list] = []
    t0 = 0
    for size in (5, 40, 150, 600, 64, 1):  # 600 > the 512 readings merge_readings takes at once
        pts = rng.uniform(-0.6, 0.6, (size, 2))
        cov = np.tile([0.004, 0.001, 0.003], (size, 1)) * rng.uniform(0.5, 2.0, (size, 1))
        t = np.arange(t0, t0 + size, dtype=np.int64)
        t0 += size
        created, merged = fs.merge_readings(pts, cov, t)
        n_before = len(ref)
        _reference_merge(ref, pts, cov, t, md)
        assert created == len(ref) - n_before and created + merged == size
    tab = fs.table()
    assert tab.id.tolist() == list(range(len(ref)))
    np.testing.assert_array_equal(np.c_[tab.x, tab.y], np.array([f[0] for f in ref]))
    np.testing.assert_array_equal(np.c_[tab.cov_xx, tab.cov_xy, tab.cov_yy], np.array([f[1] for f in ref]))
    assert tab.measured_times.tolist() == [f[2] for f in ref]
    assert tab.merges.tolist() == [f[3] for f in ref]
    assert tab.first_seen_ns.tolist() == [f[4] for f in ref]
    assert tab.last_seen_ns.tolist() == [f[5] for f in ref]
    assert max(tab.merges) >= 5  # the fixture does chain many readings into one feature


def test_a_map_without_features_has_an_empty_table_of_typed_columns() -> None:
    import dataclasses

    from pipeline.mapper import make_mapper

    grid = GridSpec(-1.0, -1.0, 0.05, 40, 40)
    for method in ("andersone", "classic"):  # classic never has features
        table = make_mapper(MapperConfig(method=method), grid).snapshot().features
        assert len(table) == 0
        for f in dataclasses.fields(table):
            col = getattr(table, f.name)
            assert isinstance(col, np.ndarray) and col.shape == (0,), (method, f.name)
            floats = f.name in ("x", "y", "cov_xx", "cov_xy", "cov_yy")
            assert col.dtype == (np.float64 if floats else np.int64), (method, f.name)


def test_feature_stamps_keep_epoch_nanoseconds() -> None:
    from mapper_helpers import build_scan

    from pipeline.mapper import make_mapper

    t = 1_700_000_000_123_456_789  # not a float64: 2**53 < t
    m = make_mapper(MapperConfig(method="andersone"), GridSpec(-3.0, -3.0, 0.05, 120, 120))
    m.begin_pass(0)
    m.integrate(build_scan([2.0, 2.5], alpha=[0.0, 1.0], t_ns=t))
    table = m.snapshot().features
    assert len(table) == 2
    assert table.first_seen_ns.dtype == table.last_seen_ns.dtype == np.int64
    assert table.first_seen_ns.tolist() == table.last_seen_ns.tolist() == [t, t]
