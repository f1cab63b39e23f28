"""evaluate's one-to-one wall matching: drawn thickness is not rewarded, surplus lines cost."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import binary_dilation

from formats.map_types import GridSpec
from pipeline.tools.evaluate import FREE, MATCHING, OCCUPIED, evaluate_maps
from pipeline.tools.wall_matching import thin

GRID = GridSpec(0.0, 0.0, 0.05, 60, 30)


def _score(run: np.ndarray, truth: np.ndarray) -> dict:  # type: ignore[type-arg]
    values, _ = evaluate_maps(run, GRID, truth, GRID, tolerance_m=0.10, poses_xy=None,
                              reach_m=None, feature_xy=np.zeros((0, 2)))
    return values


def _room() -> np.ndarray:
    truth = np.full(GRID.shape, FREE, dtype=np.int8)
    truth[15, 5:55] = OCCUPIED  # a wall 2.5 m long, one cell thick
    truth[5:25, 30] = OCCUPIED  # and one across it
    return truth


def _grown(classes: np.ndarray) -> np.ndarray:
    out = classes.copy()
    out[binary_dilation(classes == OCCUPIED, structure=np.ones((3, 3), bool))] = OCCUPIED
    return out


def test_a_wall_grown_or_thinned_scores_as_drawn() -> None:
    truth = _room()
    run = truth.copy()
    run[15, 20:24] = FREE  # a gap of 4 cells: growth by one cell does not bridge it
    base = _score(run, truth)
    assert base["matching"] == MATCHING
    assert base["precision"] == 1.0 and base["recall"] < 1.0
    grown = _score(_grown(run), truth)
    assert grown["f1"] <= base["f1"] + 0.005
    thinned = run.copy()
    thinned[(grown_cells := _grown(run) == OCCUPIED) & ~thin(grown_cells)] = FREE
    assert _score(thinned, truth)["f1"] <= base["f1"] + 0.005
    # Three cells thick, the same walls: the same score as drawn one cell thick.
    assert _score(truth, truth)["f1"] == _score(_grown(truth), truth)["f1"] == 1.0


def test_a_second_line_along_a_wall_costs_precision() -> None:
    truth = np.full(GRID.shape, FREE, dtype=np.int8)
    truth[15, 5:55] = OCCUPIED
    run = truth.copy()
    run[17, 5:55] = OCCUPIED  # 0.10 m beside the wall: within tolerance, but a second wall
    v = _score(run, truth)
    assert (v["run_occupied"], v["run_occupied_matched"]) == (100, 50)
    assert v["precision"] == 0.5 and v["recall"] == 1.0
    assert v["false_occupied"] == {"double": 50, "near_wall": 0, "in_free_space": 0,
                                   "unobserved": 0}
    assert sum(v["false_occupied"].values()) == v["run_occupied"] - v["run_occupied_matched"]


def test_a_two_cell_thick_truth_counts_once() -> None:
    truth = np.full(GRID.shape, FREE, dtype=np.int8)
    truth[15:17, 5:55] = OCCUPIED  # a laser reference's wall, two cells thick
    run = np.full(GRID.shape, FREE, dtype=np.int8)
    run[15, 5:55] = OCCUPIED
    v = _score(run, truth)
    assert v["truth_occupied_in_scope"] == 49  # thinned: one line (one end cell shorter)
    assert v["recall"] == 1.0 and v["precision"] == 49 / 50


def test_a_solid_scores_by_its_rim_whether_drawn_filled_or_as_an_outline() -> None:
    truth = np.full(GRID.shape, FREE, dtype=np.int8)
    yy, xx = np.mgrid[:30, :60]
    trunk = (yy - 15) ** 2 + (xx - 30) ** 2 <= 16  # a filled disc, radius 0.20 m
    truth[trunk] = OCCUPIED
    filled = _score(truth, truth)
    assert (filled["precision"], filled["recall"]) == (1.0, 1.0)
    outline = np.full(GRID.shape, FREE, dtype=np.int8)
    outline[trunk & binary_dilation(~trunk, structure=np.ones((3, 3), bool))] = OCCUPIED
    v = _score(outline, truth)  # the rim only, as a sonar sees it
    assert v["f1"] >= 0.95
    assert v["truth_occupied_in_scope"] == filled["truth_occupied_in_scope"]
