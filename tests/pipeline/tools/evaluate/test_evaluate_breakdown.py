"""evaluate's error breakdown: why occupied cells are false and why walls are missed."""

from __future__ import annotations

import json

import numpy as np

from formats.map_types import GridSpec
from pipeline.tools.evaluate import FREE, OCCUPIED, UNKNOWN, Evaluation, evaluate_maps

GRID = GridSpec(0.0, 0.0, 0.05, 40, 20)


def _score(run: np.ndarray, truth: np.ndarray) -> dict:  # type: ignore[type-arg]
    values, _ = evaluate_maps(run, GRID, truth, GRID, tolerance_m=0.10, poses_xy=None,
                              reach_m=None, feature_xy=np.zeros((0, 2)))
    return values


def test_false_occupied_cells_are_split_by_where_they_lie() -> None:
    truth = np.full(GRID.shape, FREE, dtype=np.int8)
    truth[:, 30:] = UNKNOWN  # behind the wall
    truth[:, 20] = OCCUPIED  # a wall along column 20 (x = 1.0 m)
    run = np.full(GRID.shape, FREE, dtype=np.int8)
    run[:, 20] = OCCUPIED  # the wall, right
    run[0, 17] = OCCUPIED  # 3 cells = 0.15 m off the wall: near
    run[5, 5] = OCCUPIED  # inside the room, far from the wall
    run[6, 6] = OCCUPIED
    run[10, 35] = OCCUPIED  # behind the wall, where the truth never saw
    v = _score(run, truth)
    assert v["false_occupied"] == {"double": 0, "near_wall": 1, "in_free_space": 2,
                                   "unobserved": 1}
    assert sum(v["false_occupied"].values()) == v["run_occupied"] - v["run_occupied_matched"]


def test_missed_wall_cells_are_split_by_what_the_run_says_there() -> None:
    truth = np.full(GRID.shape, FREE, dtype=np.int8)
    truth[:, 20] = OCCUPIED
    run = np.full(GRID.shape, UNKNOWN, dtype=np.int8)
    run[0:5, 23] = OCCUPIED  # rows 0-4: drawn 0.15 m off (missed, near a prediction)
    run[10:15, 20] = FREE  # rows 10-14: the run calls the wall free
    v = _score(run, truth)
    # rows 0-4, and rows 5-8 (row 8 is 3 columns and 4 rows = exactly 0.25 m from the
    # prediction at row 4), are near a prediction; rows 10-14 seen free; rows 9 and 15-19
    # unobserved.
    assert v["missed"] == {"near_prediction": 9, "seen_free": 5, "unobserved": 6}
    assert sum(v["missed"].values()) == v["truth_occupied_in_scope"] - v["truth_occupied_matched"]


def test_the_breakdown_round_trips_through_json_and_shows_in_the_table() -> None:
    truth = np.full(GRID.shape, FREE, dtype=np.int8)
    truth[:, 20] = OCCUPIED
    run = truth.copy()
    run[3, 3] = OCCUPIED
    values = _score(run, truth)
    ev = Evaluation(run_dir="r", truth="t", trajectory=None, reach_source="argument",
                    mean_feature_variance_m2=None, **values)
    back = Evaluation.from_dict(json.loads(ev.to_json()))
    assert back.to_dict() == ev.to_dict() and back.false_occupied["in_free_space"] == 1
    assert "near wall 0 (0.0 %), in free space 1 (100.0 %), unobserved 0" in ev.format_table()
    old = json.loads(ev.to_json())
    del old["false_occupied"], old["missed"]  # evaluation.json written before the breakdown
    assert Evaluation.from_dict(old).missed == {}
