"""regress: run versus golden directory, row by row; tolerance files."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from evaluate_helpers import (
    metrics_doc,
    shifted_wall,
    wall_probability,
    write_run,
    write_truth,
)

from formats.errors import ConfigError, FormatError, InputError
from formats.map_types import GridSpec
from pipeline.tools.evaluate import evaluate_run
from pipeline.tools.regress import (
    Regression,
    Tolerances,
    load_tolerances,
    regress,
    tolerances_toml,
)


def rows_by_metric(result: Regression) -> dict[str, bool]:
    return {r.metric: r.ok for r in result.rows}


def golden_and_run(tmp_path: Path, **run_kw: Any) -> tuple[Path, Path]:
    """A golden of 100 features with the wall map, and a run built from ``run_kw``."""
    golden = write_run(tmp_path / "golden", metrics=metrics_doc(features=100))
    run = write_run(tmp_path / "run", **run_kw)
    return golden, run


def test_identical_directories_pass(tmp_path: Path) -> None:
    golden = write_run(tmp_path / "golden")
    run = tmp_path / "run"
    shutil.copytree(golden, run)
    result = regress(run, golden)
    assert result.ok and result.failed == ()
    assert [r.metric for r in result.rows] == [
        "features", "mean_feature_variance_m2", "map_grid", "map_cells_differing",
        "readings_used",
    ]
    cells = next(r for r in result.rows if r.metric == "map_cells_differing")
    assert cells.current == 0.0 and cells.detail == "0 of 4800 cells"
    assert any("no evaluation.json" in n for n in result.notes)


@pytest.mark.parametrize(("features", "ok"), [(100, True), (98, True), (102, True),
                                              (97, False), (90, False), (103, False)])
def test_feature_count_within_two_percent(tmp_path: Path, features: int, ok: bool) -> None:
    golden, run = golden_and_run(tmp_path, metrics=metrics_doc(features=features))
    result = regress(run, golden)
    assert rows_by_metric(result)["features"] is ok
    assert result.ok is ok


def test_mean_feature_variance_within_five_percent(tmp_path: Path) -> None:
    golden = write_run(tmp_path / "golden", metrics=metrics_doc(mean_var=0.0100))
    fine = write_run(tmp_path / "fine", metrics=metrics_doc(mean_var=0.0105))
    worse = write_run(tmp_path / "worse", metrics=metrics_doc(mean_var=0.0106))
    missing = write_run(tmp_path / "missing", metrics=metrics_doc(mean_var=None))
    assert rows_by_metric(regress(fine, golden))["mean_feature_variance_m2"] is True
    assert rows_by_metric(regress(worse, golden))["mean_feature_variance_m2"] is False
    row = regress(missing, golden).failed[0]
    assert (row.metric, row.detail) == ("mean_feature_variance_m2", "missing on one side")


@pytest.mark.parametrize(("changed", "ok"), [(24, True), (48, False)])
def test_map_cells_differing(tmp_path: Path, changed: int, ok: bool) -> None:
    prob = wall_probability()
    prob.reshape(-1)[-changed:] = np.nan  # free → unknown: 0.5 % or 1 % of 4800 cells
    golden, run = golden_and_run(tmp_path, probability=prob,
                                 metrics=metrics_doc(features=100))
    result = regress(run, golden)
    row = next(r for r in result.rows if r.metric == "map_cells_differing")
    assert row.current == changed / 4800 and row.ok is ok
    assert row.detail == f"{changed} of 4800 cells"


def test_different_grid_is_a_regression(tmp_path: Path) -> None:
    grid = GridSpec(0.0, 0.0, 0.05, 80, 61)
    golden, run = golden_and_run(tmp_path, probability=np.zeros(grid.shape, np.float32),
                                 grid=grid, metrics=metrics_doc(features=100))
    result = regress(run, golden)
    assert rows_by_metric(result)["map_grid"] is False
    assert rows_by_metric(result)["map_cells_differing"] is False
    assert "80x61" in result.format_table()


def test_readings_used_exact_unless_tolerated(tmp_path: Path) -> None:
    golden, run = golden_and_run(tmp_path, metrics=metrics_doc(features=100,
                                                               readings_used=1001))
    assert rows_by_metric(regress(run, golden))["readings_used"] is False
    tol = Tolerances(readings_used_abs=1)
    assert regress(run, golden, tol).ok


def test_f1_compared_when_golden_has_evaluation(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    golden = write_run(tmp_path / "goldens" / "world")
    ev = evaluate_run(golden, truth)
    doc = ev.to_dict() | {"truth": "world.truth.yaml"}  # relative: found in a parent dir
    (golden / "evaluation.json").write_text(json.dumps(doc), encoding="utf-8")
    same = tmp_path / "same"
    shutil.copytree(golden, same)
    ok = regress(same, golden)
    assert ok.ok and ok.rows[0].metric == "f1" and ok.rows[0].current == 1.0
    bad = write_run(tmp_path / "bad", shifted_wall(5))
    result = regress(bad, golden)
    f1 = result.rows[0]
    assert (f1.metric, f1.golden, f1.current, f1.ok) == ("f1", 1.0, 0.0, False)
    assert [r.metric for r in result.failed] == ["f1", "map_cells_differing"]
    (golden / "evaluation.json").write_text(json.dumps(doc | {"truth": "gone.yaml"}),
                                            encoding="utf-8")
    with pytest.raises(InputError, match=r"evaluation\.json: golden evaluation names a truth"):
        regress(same, golden)


def test_f1_not_compared_with_a_golden_scored_by_another_rule(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    golden = write_run(tmp_path / "golden")
    doc = evaluate_run(golden, truth).to_dict()
    del doc["matching"]  # an evaluation.json written before the one-to-one rule
    (golden / "evaluation.json").write_text(json.dumps(doc), encoding="utf-8")
    result = regress(write_run(tmp_path / "bad", shifted_wall(5)), golden)
    assert "f1" not in [r.metric for r in result.rows]
    assert any("golden F1 was scored by 'distance to the nearest cell'" in n
               for n in result.notes)


def test_incomplete_directories_are_input_errors(tmp_path: Path) -> None:
    golden, run = golden_and_run(tmp_path)
    (golden / "metrics.json").unlink()
    with pytest.raises(InputError, match="golden: not a complete golden directory: missing"):
        regress(run, golden)
    with pytest.raises(InputError, match="run directory not found"):
        regress(tmp_path / "nothing", golden)


def test_golden_metrics_without_a_compared_key_are_a_format_error(tmp_path: Path) -> None:
    doc = metrics_doc()
    del doc["counts"]["readings_used"]
    golden = write_run(tmp_path / "golden", metrics=doc)
    run = write_run(tmp_path / "run")
    with pytest.raises(FormatError, match=r"metrics have no counts.readings_used") as err:
        regress(run, golden)
    assert err.value.path == str(golden / "metrics.json")
    doc = metrics_doc()
    doc["counts"]["features"] = "3"
    write_run(tmp_path / "run", metrics=doc)
    with pytest.raises(FormatError, match=r"metrics counts.features is not an integer: '3'"):
        regress(tmp_path / "run", golden)


def test_notes_name_a_different_input(tmp_path: Path) -> None:
    golden = write_run(tmp_path / "golden")
    run = write_run(tmp_path / "run", metrics=metrics_doc(sha="other"))
    result = regress(run, golden)
    assert result.ok
    assert "input log differs from the golden's (input.sha256)" in result.notes


def test_tolerances_file_round_trip(tmp_path: Path) -> None:
    p = tmp_path / "tolerances.toml"
    p.write_text(tolerances_toml(), encoding="utf-8")
    assert load_tolerances(p) == Tolerances()
    p.write_text("features_rel = 0.1\nreadings_used_abs = 3\n", encoding="utf-8")
    assert load_tolerances(p) == Tolerances(features_rel=0.1, readings_used_abs=3)
    assert load_tolerances(None) == Tolerances()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("f1 = 0.1\n", "tol.toml: unknown key 'f1' \\(known: f1_drop"),
        ("f1_drop = \n", "tol.toml: invalid TOML"),
        ("f1_drop = -0.1\n", "tol.toml: 'f1_drop' must be >= 0"),
        ("features_rel = '2 %'\n", "tol.toml: 'features_rel' must be a number"),
        ("readings_used_abs = 1.5\n", "tol.toml: 'readings_used_abs' must be an integer"),
        ("map_cells_differ = true\n", "tol.toml: 'map_cells_differ' must be a number"),
        ("f1_drop = nan\n", "tol.toml: 'f1_drop' must be >= 0"),
    ],
)
def test_tolerances_file_errors(tmp_path: Path, text: str, message: str) -> None:
    p = tmp_path / "tol.toml"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=message):
        load_tolerances(p)


def test_missing_tolerances_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"none\.toml: tolerances file not found"):
        load_tolerances(tmp_path / "none.toml")


def test_regression_to_dict(tmp_path: Path) -> None:
    golden, run = golden_and_run(tmp_path, metrics=metrics_doc(features=90))
    d = regress(run, golden).to_dict()
    assert d["ok"] is False
    row = d["rows"][0]
    assert row == {"metric": "features", "golden": 100, "current": 90, "tolerance": "±2 %",
                   "ok": False, "detail": "-10.00 %"}
