"""Scores after the trajectory's SE(2) alignment: the map's shape, not its frame's anchor."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from evaluate_helpers import TRUTH_GRID, WALL_CELLS, wall_probability, write_run, write_truth

from formats.map_types import GridSpec
from formats.writers.trajectory_csv import write_trajectory_csv
from formats.writers.trajectory_tum import write_trajectory_tum
from pipeline.tools.evaluate import FREE, OCCUPIED, UNKNOWN, evaluate_run, move_classes


def test_no_motion_keeps_the_map() -> None:
    cls = np.full((3, 4), FREE, np.int8)
    cls[1, 2] = OCCUPIED
    cls[0, 0] = UNKNOWN
    grid = GridSpec(-1.0, 2.0, 0.5, 4, 3)
    out, g = move_classes(cls, grid, (0.0, 0.0, 0.0))
    assert g == grid and np.array_equal(out, cls)


def test_whole_cell_shift_is_exact() -> None:
    cls = np.full((3, 4), FREE, np.int8)
    cls[1, 2] = OCCUPIED
    out, g = move_classes(cls, GridSpec(0.0, 0.0, 0.5, 4, 3), (1.0, -0.5, 0.0))
    assert (g.origin_x, g.origin_y, g.width, g.height) == (1.0, -0.5, 4, 3)
    assert np.array_equal(out, cls)


def test_quarter_turn_moves_a_cell_where_the_rotation_puts_it() -> None:
    cls = np.full((2, 4), FREE, np.int8)  # x ∈ [0, 2), y ∈ [0, 1) at 0.5 m
    cls[0, 3] = OCCUPIED  # centre (1.75, 0.25)
    out, g = move_classes(cls, GridSpec(0.0, 0.0, 0.5, 4, 2), (0.0, 0.0, math.pi / 2))
    # Rotated by +90°: x ∈ [−1, 0), y ∈ [0, 2); the centre goes to (−0.25, 1.75).
    assert (g.origin_x, g.origin_y, g.width, g.height) == pytest.approx((-1.0, 0.0, 2, 4))
    r, c = np.nonzero(out == OCCUPIED)
    assert (r.tolist(), c.tolist()) == ([3], [1])
    assert int((out == FREE).sum()) == 7


def test_a_turned_wall_stays_unbroken() -> None:
    cls = np.full(TRUTH_GRID.shape, FREE, np.int8)
    cls[wall_probability() > 0.5] = OCCUPIED
    out, _ = move_classes(cls, TRUTH_GRID, (0.3, -0.2, math.radians(30)))
    r, c = np.nonzero(out == OCCUPIED)
    assert r.size >= WALL_CELLS
    # Every step along the turned wall is to a neighbouring cell (8-connected, no gap).
    order = np.argsort(c, kind="stable")
    assert np.all(np.abs(np.diff(c[order])) <= 1)


def test_evaluate_scores_a_turned_run_aligned(tmp_path: Path) -> None:
    """A run whose frame is turned 10° about the trajectory's start: its map and trajectory
    are the truth's turned alike. The plain F1 falls; the aligned F1 is the truth's."""
    truth = write_truth(tmp_path)
    th = math.radians(10.0)
    moved, grid = move_classes(
        np.where(wall_probability() > 0.5, OCCUPIED, FREE).astype(np.int8), TRUTH_GRID,
        (0.0, 0.0, -th),
    )
    prob = np.where(moved == OCCUPIED, 1.0, np.where(moved == FREE, 0.0, 0.5))
    run = write_run(tmp_path / "run", prob.astype(np.float32), grid)
    t = (np.arange(5) * 1_000_000_000).astype(np.int64)
    x = np.linspace(0.5, 3.5, 5)
    y = np.full(5, 1.0)
    c, s = math.cos(-th), math.sin(-th)
    write_trajectory_tum(run / "trajectory.csv", t, c * x - s * y, s * x + c * y, np.full(5, -th))
    true_csv = tmp_path / "world.truth.csv"
    write_trajectory_csv(true_csv, t, x, y, np.zeros(5))
    ev = evaluate_run(run, truth, truth_trajectory=true_csv)
    assert ev.aligned is not None
    assert ev.aligned["alignment"][2] == pytest.approx(th)
    assert ev.f1 < 0.3
    assert ev.aligned["f1"] > 0.95
    assert "F1 aligned" in ev.format_table()
    assert evaluate_run(run, truth).aligned is None  # no true trajectory: no alignment
