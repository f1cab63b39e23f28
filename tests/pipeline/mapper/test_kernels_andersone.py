"""The compiled andersone mapper (pipeline/mapper/kernels) against the numpy reference.

The kernels replay the reference's arithmetic in its order (and draw the particles from the
same generator), so the comparisons are exact: every column of the feature table, the free
layer's update counts, the occupied layer and every counter, on synthetic, random and real
scans.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pipeline.config import MapperConfig
from pipeline.mapper.andersone import AndersoneMapper
from pipeline.mapper.features import FeatureStore
from pipeline.mapper.features_reference import FeatureSet
from pipeline.mapper.kernels.features import (
    compact_if_half_dead,
    delete_feature,
    merge_readings,
)
from pipeline.mapper.synthetic import ring_scans, room_grid
from pipeline.mapper.types import GridSpec, Scan


def _pairs(scans: list[Scan], k: int = 2) -> list[Scan]:
    """Consecutive ring firings joined ``k`` at a time (the pipeline's 0.2 s window)."""
    names = [f.name for f in dataclasses.fields(Scan)]
    return [Scan(**{n: np.concatenate([getattr(s, n) for s in scans[i : i + k]]) for n in names})
            for i in range(0, len(scans), k)]


def _assert_same_maps(cfg: MapperConfig, grid: GridSpec, scans: list[Scan]) -> AndersoneMapper:
    ref = AndersoneMapper(cfg, grid, reference=True)
    ker = AndersoneMapper(cfg, grid)
    ref.integrate_many(scans)
    ker.integrate_many(scans)
    assert ker.counters.as_dict() == ref.counters.as_dict()
    a, b = ref.snapshot(), ker.snapshot()
    for name in (f.name for f in dataclasses.fields(a.features)):
        np.testing.assert_array_equal(getattr(b.features, name), getattr(a.features, name), name)
    np.testing.assert_array_equal(ker.free_layer.counts, ref.free_layer.counts)
    np.testing.assert_array_equal(b.occupied, a.occupied)
    np.testing.assert_array_equal(b.probability, a.probability)
    assert ker.rng.bit_generator.state == ref.rng.bit_generator.state  # same draws, same count
    return ker


@pytest.mark.parametrize(
    "cfg",
    [MapperConfig(), MapperConfig(feature_correction=False),
     MapperConfig(refit_positions="cell", split_guard=False, n_particles=300, seed=3)],
    ids=["default", "no-correction", "cell-refit-no-guard-300-particles"],
)
def test_kernel_equals_reference_on_the_synthetic_room(cfg: MapperConfig) -> None:
    ker = _assert_same_maps(cfg, room_grid(0.05), _pairs(ring_scans(240)))
    c = ker.counters
    assert c.features_merged > 1000 and len(ker.feature_table()) > 100
    if cfg.feature_correction:
        assert c.features_corrected > 1000 and c.features_deleted > 10


def test_kernel_equals_reference_on_random_scans_at_grid_edges() -> None:
    """Random origins (some off the grid), beams, ranges (NaN, ±inf, below r_min, max
    range) on a small coarse grid, scans of 1-40 readings, clear_on_max_range on."""
    rng = np.random.default_rng(4)
    grid = GridSpec(-2.0, -1.5, 0.1, 40, 30)
    scans = []
    for i in range(120):
        n = int(rng.integers(1, 41))
        r = rng.uniform(0.0, 3.2, n)
        r[rng.random(n) < 0.05] = np.nan
        r[rng.random(n) < 0.05] = np.inf
        r[rng.random(n) < 0.03] = -np.inf
        r[rng.random(n) < 0.05] = 3.0  # max range
        scans.append(Scan(
            t_ns=np.full(n, 1_000 + i, dtype=np.int64),
            sensor_id=np.arange(n, dtype=np.int32),
            range_m=r,
            origin_x=rng.uniform(-2.5, 2.5, n),
            origin_y=rng.uniform(-2.0, 2.0, n),
            alpha=rng.uniform(-4.0, 4.0, n),
            fov=rng.choice([0.05, math.radians(30), math.radians(100)], n),
            min_range=np.full(n, 0.1),
            max_range=np.full(n, 3.0),
        ))
    _assert_same_maps(MapperConfig(clear_on_max_range=True, match_distance=0.3), grid, scans)


def test_kernel_merge_equals_reference_through_compaction() -> None:
    """Dense clusters (many readings per bucket, sequential re-matching), then enough
    deletions to compact the store: same features, ids and nearest-feature answers."""
    grid = GridSpec(-5.0, -5.0, 0.05, 200, 200)
    rng = np.random.default_rng(9)
    ref, ker = FeatureSet(grid, 0.15), FeatureStore(grid, 0.15)
    for _ in range(6):
        centres = rng.uniform(-5.5, 5.5, (400, 2))  # some outside the grid: border buckets
        mean = centres[rng.integers(0, 400, 1500)] + 0.05 * rng.standard_normal((1500, 2))
        cov = np.column_stack([rng.uniform(1e-4, 1e-2, 1500), rng.uniform(-1e-5, 1e-5, 1500),
                               rng.uniform(1e-4, 1e-2, 1500)])
        t = np.arange(1500, dtype=np.int64)
        want = ref.merge_readings(mean, cov, t)
        ker.reserve(1500)
        got = merge_readings(ker.arrays, mean, cov, t, 0, 1500, 0.15)
        assert tuple(got) == want
    # Delete all but every tenth feature, both stores; the kernel store compacts.
    slots = ref.alive_slots()
    doomed = slots[np.arange(slots.shape[0]) % 10 != 0]
    assert doomed.shape[0] >= 1024
    ref.delete(doomed)
    for s in doomed.tolist():
        delete_feature(ker.arrays, s)
    compact_if_half_dead(ker.arrays)
    assert ker.n == len(ker) == len(ref)
    a, b = ref.table(), ker.table()
    for name in (f.name for f in dataclasses.fields(a)):
        np.testing.assert_array_equal(getattr(b, name), getattr(a, name))
    # The rebuilt index answers like the reference.
    q = rng.uniform(-5.5, 5.5, (500, 2))
    mean = np.vstack([q, q + 0.01])
    cov = np.tile([1e-3, 0.0, 1e-3], (1000, 1))
    ker.reserve(1000)
    assert tuple(merge_readings(ker.arrays, mean, cov, np.zeros(1000, np.int64), 0, 1000, 0.15)) \
        == ref.merge_readings(mean, cov, np.zeros(1000, np.int64))
    np.testing.assert_array_equal(ker.table().x, ref.table().x)


def test_kernel_equals_reference_on_a_real_log(intel_scans) -> None:  # type: ignore[no-untyped-def]
    """The Intel lab log (real trajectory, emulated ring) as the pipeline scans it."""
    snapshot, scans = intel_scans
    assert len(scans) > 500
    ker = _assert_same_maps(MapperConfig(method="andersone"), snapshot.grid, scans)
    np.testing.assert_array_equal(ker.feature_table().x, snapshot.features.x)
