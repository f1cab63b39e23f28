"""`sonarmap evaluate` and `sonarmap regress` through typer: output, files, exit codes."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import typer
from evaluate_helpers import metrics_doc, shifted_wall, write_run, write_truth
from typer.testing import CliRunner

from cli.evaluate import register


def make_app() -> typer.Typer:
    app = typer.Typer()
    register(app)
    return app


def invoke(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(make_app(), [str(a) for a in args])
    return result.exit_code, result.stdout, result.stderr


def test_evaluate_prints_table_and_json(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    run = write_run(tmp_path / "run", shifted_wall(1))
    code, out, _ = invoke("evaluate", str(run), "--truth", str(truth))
    assert code == 0
    assert "precision" in out and "100.0 %" in out and "F1" in out
    code, out, _ = invoke("evaluate", str(run), "--truth", str(truth), "--json")
    assert code == 0
    doc = json.loads(out)
    assert doc["f1"] == 1.0 and doc["run_occupied"] == 60 and doc["recall_scope"] == "all"


def test_evaluate_output_file_and_immutable_run_dir(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    run = write_run(tmp_path / "run")
    before = sorted(p.name for p in run.iterdir())
    out_file = tmp_path / "evaluation.json"
    code, _, _ = invoke("evaluate", str(run), "--truth", str(truth), "-o", str(out_file))
    assert code == 0
    assert json.loads(out_file.read_text(encoding="utf-8"))["precision"] == 1.0
    code, _, err = invoke("evaluate", str(run), "--truth", str(truth), "-o", str(out_file))
    assert code == 1 and "exists already" in err
    code, _, err = invoke("evaluate", str(run), "--truth", str(truth),
                          "-o", str(run / "evaluation.json"))
    assert code == 1 and "is inside the run directory, an input of this command" in err
    assert sorted(p.name for p in run.iterdir()) == before


def test_evaluate_errors_are_one_line_exit_1(tmp_path: Path) -> None:
    truth = write_truth(tmp_path)
    run = write_run(tmp_path / "run")
    (run / "map.yaml").unlink()
    code, _, err = invoke("evaluate", str(run), "--truth", str(truth))
    assert code == 1
    assert err.strip() == f"sonarmap: error: {run}: not a complete run directory: missing map.yaml"


def test_regress_passes_on_identical_dirs(tmp_path: Path) -> None:
    golden = write_run(tmp_path / "golden")
    run = tmp_path / "run"
    shutil.copytree(golden, run)
    code, out, _ = invoke("regress", str(run), "--golden", str(golden))
    assert code == 0
    assert out.startswith("no regression against")
    assert "readings_used" in out and "REGRESSED" not in out


def test_regress_fails_when_features_drop(tmp_path: Path) -> None:
    golden = write_run(tmp_path / "golden", metrics=metrics_doc(features=100))
    run = write_run(tmp_path / "run", metrics=metrics_doc(features=90))
    code, out, _ = invoke("regress", str(run), "--golden", str(golden))
    assert code == 1
    assert "1 of 5 checks failed" in out
    lines = [ln for ln in out.splitlines() if "REGRESSED" in ln]
    assert len(lines) == 1 and lines[0].startswith("features ") and "-10.00 %" in lines[0]
    code, out, _ = invoke("regress", str(run), "--golden", str(golden), "--json")
    assert code == 1 and json.loads(out)["ok"] is False


def test_regress_fails_when_map_cells_differ(tmp_path: Path) -> None:
    golden = write_run(tmp_path / "golden")
    prob = shifted_wall(0)
    prob[0, :48] = float("nan")  # 48 of 4800 cells: 1 %
    run = write_run(tmp_path / "run", prob)
    code, out, _ = invoke("regress", str(run), "--golden", str(golden))
    assert code == 1
    assert "map_cells_differing" in out and "48 of 4800 cells" in out


def test_regress_tolerances_option(tmp_path: Path) -> None:
    golden = write_run(tmp_path / "golden", metrics=metrics_doc(features=100))
    run = write_run(tmp_path / "run", metrics=metrics_doc(features=90))
    tol = tmp_path / "tol.toml"
    tol.write_text("features_rel = 0.1\n", encoding="utf-8")
    code, _, _ = invoke("regress", str(run), "--golden", str(golden), "--tolerances", str(tol))
    assert code == 0
    tol.write_text("features = 0.1\n", encoding="utf-8")
    code, _, err = invoke("regress", str(run), "--golden", str(golden), "--tolerances", str(tol))
    assert code == 1 and f"{tol}: unknown key 'features'" in err


def test_evaluate_truth_trajectory_reports_ate_and_rpe(tmp_path: Path) -> None:
    from formats.writers.trajectory_csv import write_trajectory_csv
    from formats.writers.trajectory_tum import write_trajectory_tum

    truth = write_truth(tmp_path)
    run = write_run(tmp_path / "run")
    t = (np.arange(5) * 1_000_000_000).astype(np.int64)
    write_trajectory_tum(run / "trajectory.csv", t, np.array([0, 1, 2, 3, 4.4]), np.zeros(5),
                         np.zeros(5))
    true_csv = tmp_path / "world.truth.csv"
    write_trajectory_csv(true_csv, t, np.arange(5.0), np.zeros(5), np.zeros(5))
    code, out, _ = invoke("evaluate", str(run), "--truth", str(truth), "--truth-trajectory",
                          str(true_csv), "--json")
    assert code == 0
    te = json.loads(out)["trajectory_error"]
    # Estimate stretched at the end only: ATE after a best shift of 0.08 m along x.
    errs = np.array([0.08, 0.08, 0.08, 0.08, 0.32])
    assert te["ate_rmse_m"] == pytest.approx(float(np.sqrt(np.mean(errs**2))))
    assert te["rpe_pairs"] == 4 and te["rpe_trans_rmse_m"] == pytest.approx(0.2)
    code, out, _ = invoke("evaluate", str(run), "--truth", str(truth), "--truth-trajectory",
                          str(true_csv))
    assert code == 0 and "ATE (aligned)" in out and "RPE per 1 m" in out
    (run / "trajectory.csv").unlink()
    code, _, err = invoke("evaluate", str(run), "--truth", str(truth), "--truth-trajectory",
                          str(true_csv))
    assert code == 1 and "no trajectory.csv" in err and len(err.strip().splitlines()) == 1
