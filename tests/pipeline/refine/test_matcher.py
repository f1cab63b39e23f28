"""The correlative submap matcher (pipeline.refine.matcher)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.refine.matcher import LikelihoodField, SearchWindow, match
from pipeline.se2 import inverse, transform_points


def room_points() -> tuple[np.ndarray, np.ndarray]:
    """Points on the walls of an L-shaped room (every 2 cm), as single-sample arcs."""
    t = np.arange(0.0, 1.0, 0.005)
    walls = [((0, 0), (4, 0)), ((4, 0), (4, 2)), ((4, 2), (2, 2)), ((2, 2), (2, 3.5)),
             ((2, 3.5), (0, 3.5)), ((0, 3.5), (0, 0)), ((1, 1), (1.5, 1))]
    xs = np.concatenate([a[0] + t * (b[0] - a[0]) for a, b in walls])
    ys = np.concatenate([a[1] + t * (b[1] - a[1]) for a, b in walls])
    return xs, ys


KW = {"temperature": 0.02, "floor_xy": 0.02, "floor_yaw": math.radians(0.3),
      "distinct_m": 0.3, "distinct_rad": math.radians(8)}


def test_match_recovers_a_known_offset() -> None:
    x, y = room_points()
    field = LikelihoodField.of_points(x, y, res=0.05, sigma=0.1, margin=1.0)
    true_pose = np.array([1.3, 1.6, math.radians(3.0)])
    # The query: the same walls seen from true_pose (in its frame), every 3rd point.
    qx, qy = transform_points(inverse(true_pose), x[::3], y[::3])
    guess = true_pose + np.array([0.15, -0.1, math.radians(-2.5)])
    m = match(field, qx[:, None], qy[:, None], guess,
              SearchWindow(0.3, math.radians(6), 0.05, math.radians(0.5)), **KW)
    assert m.pose[0] == pytest.approx(true_pose[0], abs=0.02)
    assert m.pose[1] == pytest.approx(true_pose[1], abs=0.02)
    assert math.degrees(m.pose[2]) == pytest.approx(3.0, abs=0.3)
    assert m.score > 0.8 and m.points == qx.shape[0]
    assert np.all(np.linalg.eigvalsh(m.cov) > 0)


def test_a_corridor_leaves_its_axis_uncertain() -> None:
    t = np.arange(0.0, 10.0, 0.02)
    x = np.concatenate([t, t])
    y = np.concatenate([np.zeros_like(t), np.full_like(t, 2.0)])
    field = LikelihoodField.of_points(x, y, res=0.05, sigma=0.1, margin=1.0)
    pose = np.array([5.0, 1.0, 0.0])
    sel = (x > 3.5) & (x < 6.5)
    qx, qy = transform_points(inverse(pose), x[sel], y[sel])
    m = match(field, qx[:, None], qy[:, None], pose,
              SearchWindow(0.3, math.radians(4), 0.05, math.radians(0.5)), **KW)
    assert m.pose[1] == pytest.approx(1.0, abs=0.02)
    # Along the corridor (x) the score is flat: much larger variance than across it (y).
    assert m.cov[0, 0] > 10 * m.cov[1, 1]
    assert m.ambiguity > 0.95
