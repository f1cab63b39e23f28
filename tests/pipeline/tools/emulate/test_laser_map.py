"""The reference laser map: endpoint cells occupied, cells along beams free, rest unknown."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from emulate_helpers import laser_log

from formats.errors import ConfigError
from formats.writers.nav2_map import load_nav2_map, write_nav2_map
from pipeline.tools.emulate import LaserLog, LaserMap, LaserMapOptions, laser_occupancy_map

N_SCANS = 5


def cell(m: LaserMap, x: float, y: float) -> tuple[int, int]:
    g = m.grid
    return math.floor((y - g.origin_y) / g.resolution), math.floor((x - g.origin_x) / g.resolution)


def beam_log() -> LaserLog:
    # One echo straight ahead at 1.025 m, one no-return beam to the left (laser max 2 m).
    return laser_log(
        [[1.025, 2.0]] * N_SCANS, [0.0, 90.0], poses=[(0.0, 0.025, 0.0)] * N_SCANS, range_max=2.0
    )


def test_endpoint_occupied_beam_free_elsewhere_unknown() -> None:
    m = laser_occupancy_map(beam_log())
    end = cell(m, 1.025, 0.025)
    assert m.hits[end] == N_SCANS
    assert m.passes[end] == 0
    assert m.probability[end] > 0.99
    # Both beams of every scan start in the laser's own cell.
    assert m.passes[cell(m, 0.025, 0.025)] == 2 * N_SCANS
    for x in np.arange(0.075, 1.0, 0.05):
        c = cell(m, float(x), 0.025)
        assert m.passes[c] == N_SCANS  # each beam counts a cell it crosses once
        assert m.hits[c] == 0
        assert m.probability[c] == pytest.approx(
            1 / (1 + math.exp(-N_SCANS * math.log(0.4 / 0.6))), rel=1e-6
        )
    # The no-return beam clears free space (up to the grid edge) but marks nothing occupied.
    up = cell(m, 0.025, 0.3)
    assert m.passes[up] == N_SCANS and m.hits[up] == 0
    assert int(m.hits.sum()) == N_SCANS
    # Off the beams: never observed, unknown.
    assert math.isnan(m.probability[cell(m, 0.5, -0.3)])
    assert math.isnan(m.probability[cell(m, 1.3, 0.3)])


def test_grid_covers_poses_and_echoes_with_margin() -> None:
    m = laser_occupancy_map(beam_log(), LaserMapOptions(resolution=0.1, margin=0.5))
    g = m.grid
    assert g.resolution == 0.1
    assert g.origin_x <= -0.5 + 1e-9 and g.origin_x + g.width * 0.1 >= 1.525 - 1e-9
    assert g.origin_y <= -0.475 + 1e-9 and g.origin_y + g.height * 0.1 >= 0.525 - 1e-9
    assert m.probability.shape == g.shape and m.probability.dtype == np.float32


def test_diagonal_beam_counts_each_cell_once_and_order_does_not_matter() -> None:
    ranges = [[1.0, 1.5], [1.2, 0.7], [0.9, 1.1]]
    poses = [(0.0, 0.0, 0.3), (0.2, 0.1, -0.4), (0.1, -0.2, 1.0)]
    log = laser_log(ranges, [45.0, -30.0], poses=poses)
    m = laser_occupancy_map(log)
    assert m.passes.max() <= 3
    rev = laser_log(ranges[::-1], [45.0, -30.0], poses=poses[::-1])
    m2 = laser_occupancy_map(rev)
    np.testing.assert_array_equal(m.hits, m2.hits)
    np.testing.assert_array_equal(m.passes, m2.passes)


def test_written_nav2_map_has_the_three_classes(tmp_path: Path) -> None:
    m = laser_occupancy_map(beam_log())
    write_nav2_map(tmp_path / "laser.yaml", m.probability, m.grid)
    loaded = load_nav2_map(tmp_path / "laser.yaml")
    assert loaded.classes[cell(m, 1.025, 0.025)] == 1
    assert loaded.classes[cell(m, 0.525, 0.025)] == 0
    assert loaded.classes[cell(m, 0.5, -0.3)] == -1


def test_bad_resolution() -> None:
    with pytest.raises(ConfigError, match=r"laser map resolution must be > 0"):
        laser_occupancy_map(beam_log(), LaserMapOptions(resolution=0.0))
