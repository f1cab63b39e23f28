"""evaluate's anatomy of obliquely seen walls (pipeline.tools.oblique_walls)."""

from __future__ import annotations

import json

import numpy as np

from formats.map_types import GridSpec
from pipeline.tools.evaluate import FREE, OCCUPIED, UNKNOWN, Evaluation, evaluate_maps

GRID = GridSpec(-1.0, -2.0, 0.05, 220, 120)  # x −1…10 m, y −2…4 m


def cells(x0: float, x1: float, y0: float, y1: float) -> tuple[slice, slice]:
    """Rows and columns of the box [x0, x1) × [y0, y1) on GRID."""
    r = GRID.resolution
    return (slice(round((y0 - GRID.origin_y) / r), round((y1 - GRID.origin_y) / r)),
            slice(round((x0 - GRID.origin_x) / r), round((x1 - GRID.origin_x) / r)))


def test_walls_seen_mostly_beyond_the_angle_are_counted_with_the_ones_missed() -> None:
    truth = np.full(GRID.shape, FREE, dtype=np.int8)
    head_on = cells(4.0, 4.05, -0.5, 0.5)  # across the path, 2-4 m ahead: seen head-on
    side = cells(6.0, 8.0, 3.0, 3.05)  # along the path, 4-8 m off to the side: oblique
    truth[head_on] = OCCUPIED
    truth[side] = OCCUPIED
    run = truth.copy()
    run[side] = FREE  # the map erased the oblique wall
    path = np.column_stack([np.linspace(0.0, 2.0, 41), np.zeros(41)])
    values, _ = evaluate_maps(run, GRID, truth, GRID, tolerance_m=0.10, poses_xy=path,
                              reach_m=8.0, feature_xy=np.zeros((0, 2)), oblique_deg=30.0)
    n_side = int((truth[side] == OCCUPIED).sum())
    assert n_side == 40
    assert values["oblique"] == {"incidence_deg": 30.0, "walls": n_side, "missed": n_side,
                                 "missed_seen_free": n_side}
    # The whole side wall is seen between 53° and 70° off its normal: none beyond 75°.
    steep, _ = evaluate_maps(run, GRID, truth, GRID, tolerance_m=0.10, poses_xy=path,
                             reach_m=8.0, feature_xy=np.zeros((0, 2)), oblique_deg=75.0)
    assert steep["oblique"]["walls"] == 0
    # Hidden behind a wall at x = 5 m (y 1.2-2.8 m), the side wall is not seen at all, so
    # not obliquely either: only (some of) the 32 cells of the hiding wall can count.
    hidden = truth.copy()
    hidden[cells(5.0, 5.05, 1.2, 2.8)] = OCCUPIED
    v, _ = evaluate_maps(hidden, GRID, hidden, GRID, tolerance_m=0.10, poses_xy=path,
                         reach_m=8.0, feature_xy=np.zeros((0, 2)), oblique_deg=30.0)
    assert v["oblique"]["missed"] == 0 and v["oblique"]["walls"] <= 32
    ev = Evaluation(run_dir="r", truth="t", trajectory="p", reach_source="argument",
                    mean_feature_variance_m2=None, **values)
    back = Evaluation.from_dict(json.loads(ev.to_json()))
    assert back.oblique == ev.oblique
    assert "40 of 60 true wall cells in scope; 40 of them missed, 40 seen free" in ev.format_table()


def test_no_trajectory_or_no_angle_gives_no_count() -> None:
    truth = np.full(GRID.shape, UNKNOWN, dtype=np.int8)
    truth[cells(4.0, 4.05, -0.5, 0.5)] = OCCUPIED
    values, _ = evaluate_maps(truth, GRID, truth, GRID, tolerance_m=0.10, poses_xy=None,
                              reach_m=None, feature_xy=np.zeros((0, 2)), oblique_deg=30.0)
    assert values["oblique"] == {}
