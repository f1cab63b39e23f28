"""benchmarks.more_buildings: the default against OctoMap on a building it was not tuned on."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from benchmarks.more_buildings import emulated, main, score
from tests.benchmarks.test_buildings import box_room_log


def test_a_building_is_emulated_once_per_sonar_model(tmp_path: Path) -> None:
    log = box_room_log(tmp_path / "room-corrected.log", odometry=False)
    ideal = emulated(log, tmp_path / "work", "ideal")
    realistic = emulated(log, tmp_path / "work", "realistic")
    assert ideal.name == "room-ideal.mcap" and realistic.name == "room-realistic.mcap"
    assert ideal.with_name("room-ideal.laser.yaml").is_file()
    assert ideal.read_bytes() != realistic.read_bytes()
    stamp = ideal.stat().st_mtime_ns
    assert emulated(log, tmp_path / "work", "ideal") == ideal
    assert ideal.stat().st_mtime_ns == stamp


def test_the_room_is_scored_and_the_table_says_the_lead(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = box_room_log(tmp_path / "room-corrected.log", odometry=False)
    f1, precision, recall, octo = score(emulated(log, tmp_path / "w", "ideal"), tmp_path / "w")
    assert 0.3 < f1 <= 1 and 0 < precision <= 1 and 0 < recall <= 1
    assert math.isnan(octo) or 0 <= octo <= 1
    assert main([str(log), "--work", str(tmp_path / "w"), "--sonar-models", "ideal"]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("| room | ideal |"))
    assert f"| {f1:.3f} (" in row
    assert "ideal: mean lead" in out and "of 1" in out
