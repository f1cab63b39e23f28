"""CI regression on the sample logs: map each one and hold it to its golden.

The goldens (sample_logs/goldens/, refreshed on purpose with ``make goldens``) keep the
metrics, the map and — where the log has a ground truth — the evaluation made at refresh
time. A change that makes a map worse beyond sample_logs/goldens/tolerances.toml (F1 drop,
feature count, mean feature variance, map cells, readings used) fails here.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.app import app
from pipeline.tools.regress import load_tolerances, regress

ROOT = Path(__file__).resolve().parents[2]
GOLDENS = ROOT / "sample_logs" / "goldens"
ENTRIES = tomllib.loads((GOLDENS / "goldens.toml").read_text())["golden"]


@pytest.mark.parametrize("entry", ENTRIES, ids=[e["name"] for e in ENTRIES])
def test_sample_log_matches_its_golden(entry, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)  # the manifest's paths are repository-relative
    run_dir = tmp_path / entry["name"]
    result = CliRunner().invoke(app, ["run", entry["log"], "-o", str(run_dir), "-q", *entry.get("args", [])])
    assert result.exit_code == 0, result.output
    golden = GOLDENS / entry["name"]
    report = regress(run_dir, golden, load_tolerances(GOLDENS / "tolerances.toml"))
    assert report.ok, "\n" + report.format_table(failed_only=True)
    assert {r.metric for r in report.rows} >= {"features", "map_cells_differing", "readings_used"}
    if "truth" in entry:
        assert "f1" in {r.metric for r in report.rows}


def test_regress_command_fails_on_a_worse_map(tmp_path, monkeypatch):
    """The same log mapped with the classic grid is not the paper-method golden."""
    monkeypatch.chdir(ROOT)
    run_dir = tmp_path / "classic"
    runner = CliRunner()
    assert runner.invoke(app, ["run", "sample_logs/office/office.mcap", "-o", str(run_dir), "-q",
                               "--method", "classic"]).exit_code == 0
    result = runner.invoke(app, ["regress", str(run_dir), "--golden", str(GOLDENS / "office")])
    assert result.exit_code == 1
    assert "features" in result.output and "map_cells_differing" in result.output
