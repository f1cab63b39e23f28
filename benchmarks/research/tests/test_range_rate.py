"""The range-rate scale oracle (benchmarks/research/range_rate.py) on a sonar driving at a wall."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks.research.range_rate import LAG, range_rate_scale
from formats.map_types import GridSpec
from formats.writers.nav2_map import write_nav2_map
from pipeline.refine.echoes import ARC_SAMPLES, Echoes


def _wall_map(path: Path) -> Path:
    """An 8 × 4 m map, free but for a wall at x = 6 m (its normal along −x)."""
    grid = GridSpec(0.0, 0.0, 0.05, 160, 80)
    prob = np.zeros(grid.shape, np.float32)
    prob[:, 120] = 1.0  # cells [6.00, 6.05) m
    yaml = path / "wall.yaml"
    write_nav2_map(yaml, prob, grid)
    return yaml


def _approach(scale_error: float, *, sideways: bool = False) -> Echoes:
    """A forward sonar (0.1 m ahead of the base) reading the wall every 5 cm of a 3 m drive
    towards it (or along it, facing it, when ``sideways``); the odometry reports ``1 + k``
    times the distance driven."""
    n = 61
    travelled = np.linspace(0.0, 3.0, n)
    reported = (1.0 + scale_error) * travelled
    if sideways:  # x fixed at 2 m, driving +y from 0.5 m
        odo = np.column_stack([np.full(n, 2.0), 0.5 + reported, np.zeros(n)])
        true_x = np.full(n, 2.0)
    else:
        odo = np.column_stack([0.5 + reported, np.full(n, 2.0), np.zeros(n)])
        true_x = 0.5 + travelled
    zeros = np.zeros((n, ARC_SAMPLES))
    return Echoes(np.arange(n, dtype=np.int64) * 100_000_000, zeros, zeros, odo,
                  np.full(n, 0.1), np.zeros(n), np.zeros(n), np.full(n, math.radians(7.5)),
                  6.0 - (true_x + 0.1))


@pytest.mark.parametrize("k", [0.0, 0.03, -0.02])
def test_a_head_on_approach_gives_the_scale_error(tmp_path: Path, k: float) -> None:
    rate = range_rate_scale(_approach(k), _wall_map(tmp_path))
    assert rate.pairs == 61 - LAG
    assert rate.k_forward == pytest.approx(k, abs=2e-3)
    assert rate.k_reverse == pytest.approx(k, abs=2e-3)


def test_driving_along_the_wall_cannot_tell_the_scale(tmp_path: Path) -> None:
    # The range stays constant whatever the scale and the motion is along the wall: no
    # pair carries information, and neither fit pretends to an answer.
    rate = range_rate_scale(_approach(0.03, sideways=True), _wall_map(tmp_path))
    assert rate.pairs == 61 - LAG
    assert math.isnan(rate.k_forward) and math.isnan(rate.k_reverse)
