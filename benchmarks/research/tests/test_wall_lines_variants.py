"""Segments of the wall-lines variants (benchmarks.research.wall_lines_variants): hand-made
walls heard from a few places."""

from __future__ import annotations

import math

import numpy as np

from benchmarks.research.wall_lines_variants import vote_segments
from pipeline.mapper.kernels.lines import vote_tangents
from pipeline.mapper.types import GridSpec
from pipeline.mapper.wall_lines import LINE_BINS, empty_votes, wall_lines

GRID = GridSpec(0.0, 0.0, 0.05, 120, 120)  # 6 m × 6 m
PSI = (8 + 0.5) * math.pi / LINE_BINS  # the wall's normal: 85°, a bin's centre
HALF_FOV = math.radians(15.0)
WALL = 4.0  # the wall: x·cos PSI + y·sin PSI = WALL


def heard_from(t: np.ndarray) -> np.ndarray:
    """The votes of readings taken at ``t`` metres along a path 2 m from the wall, each
    sonar facing the wall's normal (the ideal echo: the perpendicular distance)."""
    ox = 1.0 * math.cos(PSI) + t * -math.sin(PSI) + 2.0
    oy = 1.0 * math.sin(PSI) + t * math.cos(PSI)
    r = WALL - (ox * math.cos(PSI) + oy * math.sin(PSI))
    votes = empty_votes(GRID)
    vote_tangents(ox, oy, np.full(len(t), PSI), np.full(len(t), HALF_FOV), r,
                  GRID.origin_x, GRID.origin_y, GRID.resolution, votes)
    return votes


def along(cells: np.ndarray) -> np.ndarray:
    """Each cell's offset from the wall (m) and position along it (m)."""
    rows, cols = np.nonzero(cells)
    x, y = (cols + 0.5) * GRID.resolution, (rows + 0.5) * GRID.resolution
    return np.stack([x * math.cos(PSI) + y * math.sin(PSI) - WALL,
                     y * math.cos(PSI) - x * math.sin(PSI)])


def test_two_places_far_apart_make_a_segment_the_box_test_misses() -> None:
    t = np.array([0.5, 1.3])  # two readings, 0.8 m apart: one vote per box
    votes = heard_from(t)
    on, _, _ = wall_lines(votes, GRID.resolution, 0.3)
    assert not on.any()
    seg, _, _ = vote_segments(votes, 1.0 / GRID.resolution)
    off, pos = along(seg)
    assert np.abs(off).max() <= 2 * GRID.resolution
    assert pos.max() - pos.min() >= 0.75  # from one touching point to the other
    none, _, _ = vote_segments(votes, 0.5 / GRID.resolution)
    assert not none.any()


def test_head_on_passes_run_along_each_bin_short_of_the_echo() -> None:
    from benchmarks.research.wall_lines_variants import vote_passes

    passes = np.zeros((LINE_BINS, 120, 120), dtype=np.uint16)
    one = np.array([3.0])
    vote_passes(one, one, np.array([PSI]), np.array([HALF_FOV]), np.array([1.5]),
                0.0, 0.0, GRID.resolution, passes)
    assert [b for b in range(LINE_BINS) if passes[b].any()] == [7, 8, 9]  # 75°, 85°, 95°
    rows, cols = np.nonzero(passes[8])
    x, y = (cols + 0.5) * GRID.resolution - 3.0, (rows + 0.5) * GRID.resolution - 3.0
    reach = x * math.cos(PSI) + y * math.sin(PSI)
    assert reach.min() < 0.05 and 1.4 < reach.max() <= 1.5  # from the sonar to the reach
    assert np.abs(y * math.cos(PSI) - x * math.sin(PSI)).max() <= GRID.resolution  # one ray
    assert passes[8].max() == 1  # each cell once per ray
