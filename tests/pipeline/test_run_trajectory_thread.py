"""run() writes trajectory.csv on a thread of its own beside the later mapping passes: the
same file, its error is the run's, and a run that fails leaves neither a thread nor an
output directory."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import pytest

import pipeline.run as run_module
from formats.errors import OutputError
from fuzz.harness import ROOT
from pipeline.config import Config
from pipeline.mapper.specular import SpecularMapper

LOG = ROOT / "sample_logs" / "office" / "office.mcap"
pytestmark = pytest.mark.skipif(not LOG.is_file(), reason="sample log missing")


def _trajectory_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith("sonarmap-trajectory")]


def test_the_trajectory_is_written_beside_the_later_passes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    where: list[tuple[str, int]] = []
    write = run_module._write_trajectory
    begin = SpecularMapper.begin_pass

    def noted(out: Any, track: Any) -> None:
        where.append((threading.current_thread().name, len(track)))
        write(out, track)

    def pass_begins(self: SpecularMapper, index: int) -> None:
        where.append(("pass", index))
        begin(self, index)

    monkeypatch.setattr(run_module, "_write_trajectory", noted)
    monkeypatch.setattr(SpecularMapper, "begin_pass", pass_begins)
    result = run_module.run(LOG, tmp_path / "out", Config())
    lines = (tmp_path / "out" / "trajectory.csv").read_text().splitlines()
    poses = result.metrics.counts["poses"]
    assert poses > 100 and len([ln for ln in lines if not ln.startswith("#")]) == poses
    thread, n = next(w for w in where if w[0] != "pass")
    assert thread.startswith("sonarmap-trajectory") and n == poses
    # handed over once the first pass is done, before the second begins
    assert where.index((thread, n)) == where.index(("pass", 1)) - 1
    assert _trajectory_threads() == []


def test_its_error_is_the_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def full(out: Any, track: Any) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(run_module, "_write_trajectory", full)
    with pytest.raises(OutputError, match="out: cannot write: No space left on device"):
        run_module.run(LOG, tmp_path / "out", Config())
    assert not (tmp_path / "out").exists()
    assert _trajectory_threads() == []


def test_a_run_failing_in_a_later_pass_leaves_no_thread(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    begin = SpecularMapper.begin_pass

    def fails(self: SpecularMapper, index: int) -> None:
        if index == 3:
            raise MemoryError("pass 3")
        begin(self, index)

    monkeypatch.setattr(SpecularMapper, "begin_pass", fails)
    with pytest.raises(MemoryError, match="pass 3"):
        run_module.run(LOG, tmp_path / "out", Config())
    assert not (tmp_path / "out").exists()
    assert _trajectory_threads() == []
