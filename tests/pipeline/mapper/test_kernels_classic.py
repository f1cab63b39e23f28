"""The compiled classic grid (kernels/classic_scans.py) against its numpy reference: the same
float32 log-odds and touched cells, bit for bit, on synthetic, random and real scans."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.config import MapperConfig
from pipeline.mapper.classic import ClassicMapper
from pipeline.mapper.synthetic import ring_scans, room_grid
from pipeline.mapper.types import GridSpec, Scan


def _assert_same_grids(cfg: MapperConfig, grid: GridSpec, scans: list[Scan]) -> ClassicMapper:
    ref, ker = ClassicMapper(cfg, grid, reference=True), ClassicMapper(cfg, grid)
    ref.integrate_many(scans)
    ker.integrate_many(scans)
    assert ker.counters.as_dict() == ref.counters.as_dict()
    assert ker.logodds.tobytes() == ref.logodds.tobytes()
    np.testing.assert_array_equal(ker.touched, ref.touched)
    assert ker.snapshot().probability.tobytes() == ref.snapshot().probability.tobytes()
    return ker


@pytest.mark.parametrize("cfg", [MapperConfig(method="classic"),
                                 MapperConfig(method="classic", classic_thickness_cells=4,
                                              clear_on_max_range=True)],
                         ids=["default", "thick-clearing"])
def test_kernel_equals_reference_on_the_synthetic_room(cfg: MapperConfig) -> None:
    ker = _assert_same_grids(cfg, room_grid(0.05), ring_scans(200))
    assert ker.counters.cells_freed > 10_000
    assert (ker.logodds > 0).sum() > 200  # walls occupied


def test_kernel_equals_reference_on_random_scans_at_grid_edges() -> None:
    rng = np.random.default_rng(8)
    grid = GridSpec(-2.0, -1.5, 0.1, 40, 30)
    scans = []
    for i in range(100):
        n = int(rng.integers(1, 33))
        r = rng.uniform(0.0, 3.2, n)
        r[rng.random(n) < 0.05] = np.nan
        r[rng.random(n) < 0.05] = np.inf
        r[rng.random(n) < 0.05] = 3.0
        scans.append(Scan(
            t_ns=np.full(n, i, dtype=np.int64), sensor_id=np.arange(n, dtype=np.int32),
            range_m=r, origin_x=rng.uniform(-2.5, 2.5, n), origin_y=rng.uniform(-2.0, 2.0, n),
            alpha=rng.uniform(-4.0, 4.0, n),
            fov=rng.choice([0.05, math.radians(30), math.radians(100)], n),
            min_range=np.full(n, 0.1), max_range=np.full(n, 3.0),
        ))
    cfg = MapperConfig(method="classic", clear_on_max_range=True)
    ker = _assert_same_grids(cfg, grid, scans)
    assert ker.counters.scans == 100


def test_kernel_equals_reference_on_a_real_log(intel_scans) -> None:  # type: ignore[no-untyped-def]
    snapshot, scans = intel_scans
    _assert_same_grids(MapperConfig(method="classic"), snapshot.grid, scans)
