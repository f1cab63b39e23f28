"""benchmarks.buildings: the cases of a CARMEN log the repository does not carry."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks.buildings import building_cases, building_name


def box_room_log(path: Path, odometry: bool) -> Path:
    """A robot crossing a 6 × 4 m room along y = 2, one 180-beam scan a second (and ODOM
    lines between them when ``odometry``)."""
    lines = []
    angles = np.radians(np.arange(180) - 90.0)
    for k in range(12):
        x, t = 1.0 + 0.35 * k, 10.0 + k
        dx, dy = np.cos(angles), np.sin(angles)
        with np.errstate(divide="ignore"):
            tx = np.where(dx > 0, (6 - x) / dx, np.where(dx < 0, -x / dx, np.inf))
            ty = np.where(dy > 0, 2.0 / dy, np.where(dy < 0, 2.0 / -dy, np.inf))
        r = " ".join(f"{v:.3f}" for v in np.minimum(tx, ty))
        lines.append(f"FLASER 180 {r} {x} 2.0 0.0 {x} 2.0 0.0 {t} host {t}")
        if odometry:
            lines.append(f"ODOM {x} 2.0 0.0 0.35 0 0 {t - 0.5} host {t - 0.5}")
            lines.append(f"ODOM {x + 0.01} 2.0 0.0 0.35 0 0 {t + 0.5} host {t + 0.5}")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_building_is_named_by_its_file() -> None:
    assert building_name(Path("data/aces-corrected.log.gz")) == "aces"
    assert building_name(Path("freiburg-079-corrected.log")) == "freiburg-079"


@pytest.mark.parametrize("odometry", [True, False])
def test_a_building_gives_its_drifted_case_and_its_odometry_where_it_has_one(
        tmp_path: Path, odometry: bool) -> None:
    log = box_room_log(tmp_path / "room-corrected.log", odometry)
    cases = building_cases(log, tmp_path / "work")
    names = [c[0] for c in cases]
    assert names == (["room", "room, real odometry"] if odometry else ["room"])
    for _, clean, logged, truth, trajectory in cases:
        assert clean == tmp_path / "work" / "room" / "room.mcap" and clean.exists()
        assert logged.exists() and logged != clean
        assert truth.name == "room.laser.yaml" and trajectory.name == "room.truth.csv"
    # the drifted log's own truth is the corrected trajectory: the same file beside it
    drifted_truth = cases[0][2].with_name("room-drifted.truth.csv").read_text()
    assert drifted_truth == cases[0][4].read_text()
    first = [float(v) for v in drifted_truth.splitlines()[1].split(",")]
    assert first[1:3] == [1.0, 2.0] and math.isclose(first[3], 0.0)
    # made once: asking again reuses the logs
    stamp = cases[0][2].stat().st_mtime_ns
    assert building_cases(log, tmp_path / "work", odometry=odometry) == cases
    assert cases[0][2].stat().st_mtime_ns == stamp
