"""Path length along a track and the echoes pooled into submaps (pipeline.refine.submaps)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.refine.echoes import Echoes
from pipeline.refine.submaps import build_submaps, path_length, path_length_at


def test_path_length_sums_the_steps_from_the_first_pose() -> None:
    # a 3-4-5 step, then back along x by 2 (path length counts every metre driven)
    x, y = np.array([0.0, 3.0, 1.0]), np.array([0.0, 4.0, 4.0])
    np.testing.assert_allclose(path_length(x, y), [0.0, 5.0, 7.0])
    assert path_length(np.array([2.0]), np.array([1.0])).tolist() == [0.0]
    assert path_length(np.empty(0), np.empty(0)).shape == (0,)


def test_path_length_at_stamps_is_linear_between_poses() -> None:
    t = np.array([100, 200, 400], np.int64)
    x, y = np.array([0.0, 1.0, 3.0]), np.zeros(3)
    got = path_length_at(t, x, y, np.array([100, 150, 300, 400, 500], np.int64))
    np.testing.assert_allclose(got, [0.0, 0.5, 2.0, 3.0, 3.0])  # held at the ends


def _echoes_along_x(n: int, spacing: float) -> Echoes:
    """``n`` echoes of one forward sonar (1 m, its arc 3 points) on a track along +x."""
    t = np.arange(n, dtype=np.int64) * 10**8
    odo = np.column_stack([np.arange(n) * spacing, np.zeros(n), np.zeros(n)])
    return Echoes(t, np.ones((n, 3)), np.array([[-0.1, 0.0, 0.1]] * n), odo,
                  np.zeros(n), np.zeros(n), np.zeros(n), np.full(n, 0.1), np.ones(n))


def test_submaps_pool_the_echoes_per_stretch_of_path_in_their_anchors_frame() -> None:
    echoes = _echoes_along_x(40, 0.1)  # 3.9 m of path
    path = echoes.odo[:, 0].copy()
    maps = build_submaps(echoes, path, travel_m=1.0, min_echoes=5, max_points=100)
    assert [len(m) for m in maps] == [10, 10, 10, 10]
    m = maps[1]  # echoes 10-19: anchor the middle one's odometry pose
    assert m.t_ns == 15 * 10**8 and m.path_m == pytest.approx(1.5)
    np.testing.assert_allclose(m.anchor, [1.5, 0.0, 0.0])
    # the points in the anchor frame: each echo's arc moved by its pose relative to it
    np.testing.assert_allclose(m.px[:, 1], np.arange(10) * 0.1 - 0.5 + 1.0, atol=1e-12)
    np.testing.assert_allclose(m.py[0], [-0.1, 0.0, 0.1], atol=1e-12)


def test_a_short_stretch_joins_the_next_submap_and_a_short_tail_the_one_before() -> None:
    echoes = _echoes_along_x(25, 0.1)  # stretches of 10, 10 and a tail of 5 echoes
    path = echoes.odo[:, 0].copy()
    assert [len(m) for m in build_submaps(echoes, path, travel_m=1.0, min_echoes=6,
                                          max_points=100)] == [10, 15]
    # fewer echoes than a submap needs anywhere: one submap of them all
    assert [len(m) for m in build_submaps(echoes, path, travel_m=1.0, min_echoes=30,
                                          max_points=100)] == [25]
    assert build_submaps(echoes.take(np.arange(0)), path[:0], travel_m=1.0, min_echoes=1,
                         max_points=10) == []


def test_a_submap_keeps_at_most_max_points_echoes_evenly() -> None:
    echoes = _echoes_along_x(21, 0.01)
    maps = build_submaps(echoes, echoes.odo[:, 0].copy(), travel_m=1.0, min_echoes=1,
                         max_points=5)
    assert len(maps) == 1 and len(maps[0]) == 5
    # echoes 0, 5, 10, 15, 20 kept: their arcs' centres 1 m ahead of each, anchor at echo 10
    np.testing.assert_allclose(maps[0].px[:, 1], 1.0 + (np.arange(0, 21, 5) - 10) * 0.01,
                               atol=1e-12)
    assert math.isclose(maps[0].path_m, 0.1)
