"""CI regression on the sample logs: map each log of the project's suite and hold it to
its golden.

The suite (sample_logs/goldens/suite.toml) lists the logs, their truths and
configurations; the goldens beside it (refreshed on purpose with ``make goldens``, which is
``sonarmap regress --suite ... --update``) keep the metrics, the map and — where the log
has a ground truth — the evaluation made at refresh time. A change that makes a map worse
beyond sample_logs/goldens/tolerances.toml (F1 drop, feature count, mean feature variance,
map cells, readings used) fails here. Each log runs through the suite's own worker
function (:func:`pipeline.tools.suite.check.check_log`), one test each so that the test
workers share them; the Dask driver around it is tested on a tiny suite in
tests/pipeline/tools/suite.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.app import app
from pipeline.tools.regress import load_tolerances
from pipeline.tools.suite.check import CheckJob, check_log
from pipeline.tools.suite.golden_dir import GOLDEN_MARKER, golden_refusal
from pipeline.tools.suite.run_suite import plan_log
from pipeline.tools.suite.suite_file import read_suite

ROOT = Path(__file__).resolve().parents[2]
GOLDENS = ROOT / "sample_logs" / "goldens"
SUITE = read_suite(GOLDENS / "suite.toml")


@pytest.mark.parametrize("log", SUITE.logs, ids=[log.name for log in SUITE.logs])
def test_sample_log_matches_its_golden(log, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)  # goldens record repository-relative paths
    tol = load_tolerances(SUITE.tolerances)
    job = plan_log(log, SUITE, GOLDENS, False, tol, tmp_path, None)
    assert isinstance(job, CheckJob), job
    result = check_log(job)
    assert result.status == "ok", f"{result.reason}\n" + "\n".join(
        f"{r['metric']}: golden {r['golden']}, current {r['current']}" for r in result.failed_rows)
    assert {r["metric"] for r in result.rows} >= {"features", "map_cells_differing",
                                                  "readings_used"}
    if log.truth is not None:
        assert "f1" in {r["metric"] for r in result.rows}
    # Every golden is one --update may refresh: the marker, nothing but its files.
    assert (GOLDENS / log.name / GOLDEN_MARKER).is_file()
    assert golden_refusal(GOLDENS / log.name) is None


def test_every_golden_directory_is_in_the_suite():
    """A golden nobody refreshes would go stale: each one is a log of the suite."""
    dirs = {p.name for p in GOLDENS.iterdir() if (p / "metrics.json").is_file()}
    assert dirs == {log.name for log in SUITE.logs}


def test_regress_command_fails_on_a_worse_map(tmp_path, monkeypatch):
    """The same log mapped with the classic grid is not the default-method golden."""
    monkeypatch.chdir(ROOT)
    run_dir = tmp_path / "classic"
    runner = CliRunner()
    assert runner.invoke(app, ["run", "sample_logs/office/office.mcap", "-o", str(run_dir), "-q",
                               "--method", "classic"]).exit_code == 0
    result = runner.invoke(app, ["regress", str(run_dir), "--golden", str(GOLDENS / "office")])
    assert result.exit_code == 1
    assert "features" in result.output and "map_cells_differing" in result.output
