"""End to end: a simulated log mapped by pipeline.run, evaluated and regressed."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from pipeline.config import Config
from pipeline.tools.evaluate import evaluate_run
from pipeline.tools.regress import regress

REPO = Path(__file__).resolve().parents[4]
WORLD = REPO / "sample_logs" / "worlds" / "corridor.toml"


@pytest.mark.skipif(not WORLD.is_file(), reason="corridor world not in this checkout")
def test_simulated_run_evaluates_and_regresses(tmp_path: Path) -> None:
    from pipeline.run import run
    from pipeline.tools.simulate import run_simulation

    log, truth, _pgm, traj = run_simulation(WORLD, tmp_path / "corridor.mcap", "mcap")
    result = run(log, tmp_path / "run", Config())
    ev = evaluate_run(tmp_path / "run", truth, trajectory=traj, sensor_reach_m=5.0)
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text(encoding="utf-8"))
    # What evaluate reads is what the pipeline wrote.
    assert ev.features == metrics["counts"]["features"] == len(result.snapshot.features)
    assert ev.mean_feature_variance_m2 == pytest.approx(
        metrics["paper_metric"]["mean_feature_variance_m2"], rel=1e-9
    )
    assert ev.recall_scope == "within_reach" and ev.truth_occupied_in_scope > 0
    assert ev.run_occupied > 0 and 0.0 < ev.f1 <= 1.0
    assert ev.feature_distance_mean_m is not None and ev.feature_distance_mean_m >= 0.0
    assert ev == evaluate_run(tmp_path / "run", truth, trajectory=traj, sensor_reach_m=5.0)
    # The run as its own golden, with the evaluation the golden refresh would store.
    golden = tmp_path / "golden"
    shutil.copytree(tmp_path / "run", golden)
    (golden / "evaluation.json").write_text(ev.to_json(), encoding="utf-8")
    reg = regress(tmp_path / "run", golden)
    assert reg.ok, reg.format_table()
    assert reg.rows[0].metric == "f1" and reg.rows[0].current == pytest.approx(ev.f1, abs=1e-11)
