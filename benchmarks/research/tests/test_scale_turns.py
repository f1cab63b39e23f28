"""benchmarks.research.scale_turns: a log turned as a whole, its echoes with it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.research.scale_turns import turned, turned_echoes
from pipeline.refine import Echoes


def test_a_turn_rotates_positions_about_the_origin_and_adds_to_the_heading() -> None:
    x, y, yaw = turned(np.array([1.0, 0.0]), np.array([0.0, 2.0]), np.array([0.0, 3.0]),
                       math.pi / 2)
    assert x == pytest.approx([0.0, -2.0], abs=1e-12)
    assert y == pytest.approx([1.0, 0.0], abs=1e-12)
    assert yaw == pytest.approx([math.pi / 2, 3.0 + math.pi / 2 - 2 * math.pi])


def test_turned_echoes_move_their_poses_and_keep_their_arcs() -> None:
    n = 2
    echoes = Echoes(t_ns=np.array([1, 2]), bx=np.ones((n, 3)), by=np.zeros((n, 3)),
                    odo=np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.5]]), sx=np.zeros(n),
                    sy=np.zeros(n), axis=np.zeros(n), half=np.full(n, 0.2),
                    range_m=np.array([1.0, 2.0]))
    out = turned_echoes(echoes, math.pi)
    assert out.odo == pytest.approx(np.array([[-1.0, 0.0, -math.pi], [0.0, -1.0, 0.5 - math.pi]]),
                                    abs=1e-12)
    assert out.bx is echoes.bx and out.range_m is echoes.range_m
    assert echoes.odo[0, 0] == 1.0  # the given echoes are left as they were
