"""``emulate`` reads its laser log from a URL: the same sonar log as from the local file."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.app import app

ROOT = Path(__file__).resolve().parents[2]
LAB = ROOT / "sample_logs" / "intel-lab"
ARGS = ["--max-scans", "20", "--resolution", "0.1"]


@pytest.mark.parametrize("name", ["intel-corrected.log.gz"])
def test_emulate_from_a_url_writes_what_the_local_file_gives(name, http, http_root, tmp_path):
    """A CARMEN log (text: downloaded to a temporary file, removed after). ROS laser logs
    go through the readers the run tests read from URLs."""
    shutil.copy(LAB / name, http_root / name)
    runner = CliRunner()
    local = runner.invoke(app, ["emulate", str(LAB / name), "-o", str(tmp_path / "a.mcap"),
                                *ARGS])
    assert local.exit_code == 0, local.output
    remote = runner.invoke(app, ["emulate", f"{http.url}/{name}", "-o",
                                 str(tmp_path / "b.mcap"), *ARGS])
    assert remote.exit_code == 0, remote.output
    for a, b in (("a.mcap", "b.mcap"), ("a.laser.pgm", "b.laser.pgm"),
                 ("a.truth.csv", "b.truth.csv")):
        assert (tmp_path / a).read_bytes() == (tmp_path / b).read_bytes(), a
