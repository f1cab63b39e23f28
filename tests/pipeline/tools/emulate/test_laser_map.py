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


def _room_ranges(poses: list[tuple[float, float, float]], angles_deg: np.ndarray,
                 half: float) -> np.ndarray:
    """Noiseless ranges from each pose to the walls of the square room |x|, |y| = half."""
    out = np.empty((len(poses), angles_deg.size))
    for i, (x, y, yaw) in enumerate(poses):
        th = yaw + np.radians(angles_deg)
        c, s = np.cos(th), np.sin(th)
        with np.errstate(divide="ignore"):
            tx = np.where(c > 0, (half - x) / c, np.where(c < 0, (-half - x) / c, np.inf))
            ty = np.where(s > 0, (half - y) / s, np.where(s < 0, (-half - y) / s, np.inf))
        out[i] = np.minimum(tx, ty)
    return out


def test_noiseless_room_walls_are_one_or_two_cells_thick() -> None:
    half = 1.98
    angles = np.arange(-180.0, 180.0, 0.5)
    rng = np.random.default_rng(5)
    poses = [(float(x), float(y), float(t)) for x, y, t in
             zip(rng.uniform(-1.2, 1.2, 40), rng.uniform(-1.2, 1.2, 40),
                 rng.uniform(-np.pi, np.pi, 40), strict=True)]
    log = laser_log(_room_ranges(poses, angles, half), angles, poses=poses)
    m = laser_occupancy_map(log)
    g = m.grid
    wall = m.probability > 0.65
    xs = g.origin_x + (np.arange(g.width) + 0.5) * g.resolution
    ys = g.origin_y + (np.arange(g.height) + 0.5) * g.resolution
    inner = (np.abs(xs) < half - 0.3)
    # Across each wall, along every row/column away from the corners: 1 or 2 wall cells.
    for side in (-1, 1):
        band_x = np.abs(xs - side * half) < 0.3  # columns around the wall x = ±half
        band_y = np.abs(ys - side * half) < 0.3
        across_x = wall[np.ix_(np.abs(ys) < half - 0.3, band_x)].sum(axis=1)
        across_y = wall[np.ix_(band_y, inner)].sum(axis=0)
        assert set(across_x.tolist()) <= {1, 2} and across_x.min() == 1
        assert set(across_y.tolist()) <= {1, 2}
    # Nothing inside the room is a wall.
    assert not wall[np.ix_(np.abs(ys) < half - 0.3, inner)].any()


def test_a_wall_needs_two_hits_and_a_fair_share_of_the_beams() -> None:
    # One beam ends in a cell once: not a wall (one stray hit), but not free either.
    one = laser_occupancy_map(laser_log([[1.025]], [0.0], poses=[(0.0, 0.025, 0.0)]))
    end = cell(one, 1.025, 0.025)
    assert one.hits[end] == 1 and one.probability[end] == 0.5
    # Three hits, but 11 beams pass through: log-odds say occupied (p 0.89), the share
    # (3 of 14 beams, under 0.25) says the laser does not hit it consistently.
    ranges = [[1.025, 1.5]] * 3 + [[1.5, 1.5]] * 4
    m = laser_occupancy_map(laser_log(ranges, [0.0, 0.0], poses=[(0.0, 0.025, 0.0)] * 7))
    c = cell(m, 1.025, 0.025)
    assert m.hits[c] == 3 and m.passes[c] == 11
    assert m.probability[c] == 0.5
    ranges = [[1.025, 1.025]] * 2 + [[1.5, 1.5]] * 2
    m = laser_occupancy_map(laser_log(ranges, [0.0, 0.0], poses=[(0.0, 0.025, 0.0)] * 4))
    c = cell(m, 1.025, 0.025)
    assert m.hits[c] == 4 and m.passes[c] == 4
    assert m.probability[c] > 0.65  # half the beams end there: a wall
