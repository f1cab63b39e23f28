"""evaluate_run: precision/recall/F1, free space, reach, resampling, features, errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from evaluate_helpers import (
    TRUTH_GRID,
    WALL_CELLS,
    features_at,
    metrics_doc,
    shifted_wall,
    wall_probability,
    write_run,
    write_truth,
)

from formats.errors import ConfigError, FormatError, InputError
from formats.map_types import GridSpec
from formats.writers.trajectory_csv import read_trajectory
from pipeline.tools.evaluate import (
    Evaluation,
    evaluate_run,
    resample_classes,
    run_sensor_reach,
)

FREE_CELLS = 80 * 60 - WALL_CELLS


def test_perfect_run_scores_one(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    run = write_run(tmp_path / "run")
    ev = evaluate_run(run, truth)
    assert (ev.precision, ev.recall, ev.f1) == (1.0, 1.0, 1.0)
    assert ev.run_occupied == ev.run_occupied_matched == WALL_CELLS
    assert ev.truth_occupied_in_scope == ev.truth_occupied_matched == WALL_CELLS
    assert ev.free_accuracy == 1.0 and ev.run_free == FREE_CELLS
    assert ev.unknown_fraction == 0.0 and ev.truth_known_in_scope == 80 * 60
    assert ev.recall_scope == "all" and ev.reach_source == "unknown"
    assert any("no trajectory" in n for n in ev.notes)
    # Features at 0, 0.3 and 0.4 m from the nearest wall cell centre.
    assert ev.features == 3
    assert ev.feature_distance_mean_m == pytest.approx(0.7 / 3, abs=1e-12)
    assert ev.feature_distance_median_m == pytest.approx(0.3, abs=1e-12)
    assert ev.mean_feature_variance_m2 == 0.0123


@pytest.mark.parametrize("rows", [1, 2, -2])
def test_shift_within_tolerance_still_matches(tmp_path: Path, rows: int) -> None:
    truth = write_truth(tmp_path)
    run = write_run(tmp_path / "run", shifted_wall(rows))
    ev = evaluate_run(run, truth, tolerance_m=0.10)
    assert (ev.precision, ev.recall, ev.f1) == (1.0, 1.0, 1.0)
    # The true wall's cells are free in the shifted map: those are the only free errors.
    assert ev.run_free == FREE_CELLS
    assert ev.run_free_correct == FREE_CELLS - WALL_CELLS
    assert ev.free_accuracy == pytest.approx((FREE_CELLS - WALL_CELLS) / FREE_CELLS)


def test_shift_beyond_tolerance_scores_zero(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    run = write_run(tmp_path / "run", shifted_wall(5))
    ev = evaluate_run(run, truth, tolerance_m=0.10)
    assert (ev.precision, ev.recall, ev.f1) == (0.0, 0.0, 0.0)
    assert ev.run_occupied == WALL_CELLS and ev.run_occupied_matched == 0
    # A looser tolerance (0.25 m = 5 cells) accepts the same map.
    assert evaluate_run(run, truth, tolerance_m=0.25).f1 == 1.0
    assert evaluate_run(run, truth, tolerance_m=0.24).f1 == 0.0


def test_half_wall_recall_counts_one_true_cell_per_run_cell(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    run = write_run(tmp_path / "run", wall_probability(cols=slice(40, 70)))
    ev = evaluate_run(run, truth)
    assert ev.precision == 1.0
    # 30 run cells pair with 30 true cells (one each), though true cells 38 and 39 also lie
    # within 0.10 m of the run's first cell.
    assert ev.truth_occupied_matched == 30
    assert ev.recall == 30 / 60
    assert ev.f1 == pytest.approx(2 * 0.5 / 1.5)


def test_empty_run_recall_zero_precision_undefined(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    run = write_run(tmp_path / "run", np.zeros(TRUTH_GRID.shape, np.float32),
                    features=features_at([]), metrics=metrics_doc(features=0, mean_var=None))
    ev = evaluate_run(run, truth)
    assert (ev.precision, ev.recall, ev.f1) == (0.0, 0.0, 0.0)
    assert ev.run_occupied == 0 and ev.truth_occupied_matched == 0
    assert any("precision undefined" in n for n in ev.notes)
    assert ev.features == 0 and ev.feature_distance_mean_m is None
    assert ev.mean_feature_variance_m2 is None
    assert any("no features" in n for n in ev.notes)


def test_all_unknown_run(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    run = write_run(tmp_path / "run", np.full(TRUTH_GRID.shape, np.nan, np.float32))
    ev = evaluate_run(run, truth)
    assert ev.unknown_fraction == 1.0
    assert ev.free_accuracy is None and ev.run_free == 0
    assert ev.recall == 0.0


def test_coarser_run_with_other_origin_is_resampled(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    # 0.1 m cells from (-0.5, -0.3): row 18 covers y ∈ [1.5, 1.6), cols 10..39 x ∈ [0.5, 3.5).
    grid = GridSpec(-0.5, -0.3, 0.1, 50, 36)
    prob = np.zeros(grid.shape, np.float32)
    prob[18, 10:40] = 1.0
    prob[0, 0] = 1.0  # centre (-0.45, -0.25): outside the truth map
    run = write_run(tmp_path / "run", prob, grid)
    ev = evaluate_run(run, truth)
    # Each coarse cell covers 2×2 truth cells: the wall becomes truth rows 30 and 31, thinned
    # to one line of 59 cells (thinning shortens a two-cell-thick bar by one cell); the
    # phantom outside the truth map becomes 2×2 cells of the extended grid, thinned to one.
    assert ev.run_occupied == WALL_CELLS - 1 + 1
    assert ev.run_occupied_outside == 1
    assert ev.run_occupied_matched == WALL_CELLS - 1
    assert ev.precision == 59 / 60 and ev.recall == 59 / 60
    assert any("1 run wall cell(s) lie outside the truth map" in n for n in ev.notes)
    assert ev.unknown_fraction == 0.0


def test_partial_run_map_leaves_the_rest_unknown(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    grid = GridSpec(2.0, 0.0, 0.05, 40, 60)  # covers x ∈ [2, 4) only
    run = write_run(tmp_path / "run", wall_probability(grid, cols=slice(0, 30)), grid)
    ev = evaluate_run(run, truth)
    assert ev.precision == 1.0 and ev.recall == 30 / 60
    assert ev.unknown_fraction == 0.5  # truth columns 0..39 are outside the run map


def test_finer_run_keeps_thin_walls(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    grid = GridSpec(0.0, 0.0, 0.025, 160, 120)
    prob = np.zeros(grid.shape, np.float32)
    prob[60, 20:140] = 1.0  # y ∈ [1.5, 1.525): the lower half of truth row 30
    run = write_run(tmp_path / "run", prob, grid)
    ev = evaluate_run(run, truth)
    assert (ev.precision, ev.recall) == (1.0, 1.0)
    assert ev.run_occupied == WALL_CELLS


def test_resample_classes_direct() -> None:
    src = GridSpec(1.0, 1.0, 1.0, 2, 2)
    classes = np.array([[1, 0], [-1, 1]], dtype=np.int8)
    dst = GridSpec(0.0, 0.0, 1.0, 4, 3)
    out, outside = resample_classes(classes, src, dst)
    expected = np.full((3, 4), -1, np.int8)
    expected[1:3, 1:3] = classes
    np.testing.assert_array_equal(out, expected)
    assert outside == 0
    small = GridSpec(1.0, 1.0, 1.0, 1, 1)
    out, outside = resample_classes(classes, src, small)
    assert out.tolist() == [[1]] and outside == 1


def test_recall_scope_follows_trajectory_and_reach(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    run = write_run(tmp_path / "run", wall_probability(cols=slice(40, 41)))
    traj = tmp_path / "world.truth.csv"
    # One pose on the centre of cell (row 20, col 40), 0.5 m below the wall cell at col 40.
    traj.write_text("t,x,y,yaw\n0.0,2.025,1.025,0.0\n0.1,2.025,1.025,0.0\n", encoding="utf-8")
    ev = evaluate_run(run, truth, trajectory=traj, sensor_reach_m=0.5)
    assert ev.recall_scope == "within_reach" and ev.reach_source == "argument"
    assert ev.truth_occupied_in_scope == 1 and ev.recall == 1.0
    # Cells within 10 cells of a cell centre: the Gauss circle count N(10) = 317.
    assert ev.truth_known_in_scope == 317
    assert ev.precision == 1.0
    # The run cell pairs with the true cell in scope, not with its neighbours 38, 39, 41
    # and 42 (as close, but out of scope).
    assert ev.truth_occupied_matched == 1
    everything = evaluate_run(run, truth)
    # Over the whole wall: the one run cell pairs with one true cell.
    assert everything.truth_occupied_in_scope == WALL_CELLS
    assert everything.recall == 1 / WALL_CELLS


def test_reach_from_config_and_metrics(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    traj = tmp_path / "t.csv"
    traj.write_text("0.0,2.025,1.025,0.0\n", encoding="utf-8")  # no header: t,x,y,yaw
    run = write_run(tmp_path / "cfg", config_toml="[sensors]\nmax_range = 0.5\n")
    ev = evaluate_run(run, truth, trajectory=traj)
    assert (ev.reach_m, ev.reach_source) == (0.5, "config.toml")
    assert ev.truth_occupied_in_scope == 1
    preset = write_run(tmp_path / "preset", config_toml='[sensors]\npreset = "pioneer-p3dx"\n')
    assert run_sensor_reach(preset, {}) == (5.0, "config.toml")
    doc = metrics_doc()
    doc["input"]["max_range_m"] = 3.0
    assert run_sensor_reach(tmp_path / "nowhere", doc) == (3.0, "metrics.json")
    doc["input"]["max_range_m"] = None  # a sensor row's max_range_m is not a source (run writes none)
    doc["sensors"][0]["max_range_m"] = 3.0
    assert run_sensor_reach(tmp_path / "nowhere", doc) == (None, "unknown")
    bare = write_run(tmp_path / "bare")
    ev = evaluate_run(bare, truth, trajectory=traj)
    assert ev.recall_scope == "all" and ev.reach_m is None
    assert any("no known sensor reach" in n for n in ev.notes)


def test_results_are_deterministic_and_round_trip(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    run = write_run(tmp_path / "run", shifted_wall(1))
    a, b = evaluate_run(run, truth), evaluate_run(run, truth)
    assert a == b and a.to_json() == b.to_json()
    again = Evaluation.from_dict(json.loads(a.to_json()))
    assert again.to_dict() == a.to_dict()
    table = a.format_table()
    assert "precision" in table and "F1" in table and "1.0000" in table
    with pytest.raises(FormatError, match="evaluation has no f1"):
        Evaluation.from_dict({k: v for k, v in a.to_dict().items() if k != "f1"}, "e.json")


def test_missing_run_files_are_input_errors(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    run = write_run(tmp_path / "run")
    (run / "features.parquet").unlink()
    with pytest.raises(InputError, match=r"run: not a complete run directory: missing features"):
        evaluate_run(run, truth)
    with pytest.raises(InputError, match="run directory not found"):
        evaluate_run(tmp_path / "absent", truth)


def test_unreadable_inputs_are_format_errors(tmp_path: Path) -> None:
    run = write_run(tmp_path / "run")
    bad = tmp_path / "bad.yaml"
    bad.write_text("image: [unclosed\n", encoding="utf-8")
    with pytest.raises(FormatError, match=r"bad\.yaml: not a readable map YAML"):
        evaluate_run(run, bad)
    truth = write_truth(tmp_path)
    (run / "metrics.json").write_text("{not json", encoding="utf-8")
    with pytest.raises(FormatError, match=r"metrics.json: not valid JSON"):
        evaluate_run(run, truth)
    with pytest.raises(ConfigError, match="tolerance must be"):
        evaluate_run(run, truth, tolerance_m=-1.0)


def test_trajectory_errors(tmp_path: Path) -> None:
    """--trajectory reads the truth CSV through the one trajectory reader."""
    p = tmp_path / "traj.csv"
    p.write_text("t,a,b\n1,2,3\n", encoding="utf-8")
    with pytest.raises(FormatError, match=r"traj\.csv: trajectory header has no x, y, yaw column"):
        read_trajectory(p)
    p.write_text("t,x,y,yaw\n1,2,oops,0\n", encoding="utf-8")
    with pytest.raises(FormatError, match=r"traj\.csv: line 2: not a t,x,y,yaw row"):
        read_trajectory(p)
    p.write_text("t,x,y,yaw\n", encoding="utf-8")
    with pytest.raises(FormatError, match="header but no poses"):
        read_trajectory(p)
    with pytest.raises(InputError, match="trajectory file not found"):
        read_trajectory(tmp_path / "none.csv")
    p.write_text("# true poses\nyaw,y,x,t\n0,1.5,2.5,0\n0,1.0,3.0,1\n", encoding="utf-8")
    np.testing.assert_array_equal(read_trajectory(p).xy, [[2.5, 1.5], [3.0, 1.0]])
