"""trajectory.csv in the TUM layout: exact lines, evo's parsing rules, round trip."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from formats.errors import FormatError
from formats.writers.trajectory_tum import read_trajectory_tum, write_trajectory_tum

T = np.array([1_700_000_000_000_000_000, 1_700_000_000_050_000_001, 1_700_000_001_000_000_000])
X = np.array([1.5, 1.525, -2.0])
Y = np.array([1.5, 1.5, 3.25])
YAW = np.array([0.0, math.pi / 2, -3.0])


def test_exact_lines(tmp_path: Path) -> None:
    p = tmp_path / "trajectory.csv"
    write_trajectory_tum(p, T, X, Y, YAW, frame="odom")
    lines = p.read_text().splitlines()
    assert lines[0] == "# t x y z qx qy qz qw  (TUM RGB-D; frame: odom; yaw = 2*atan2(qz, qw))"
    assert lines[1] == "1700000000.000000000 1.500000000 1.500000000 0 0 0 0.000000000 1.000000000"
    assert lines[2] == "1700000000.050000001 1.525000000 1.500000000 0 0 0 0.707106781 0.707106781"
    assert lines[3].startswith("1700000001.000000000 -2.000000000 3.250000000 0 0 0 -0.997494987 ")
    assert len(lines) == 4


def test_evo_reads_it(tmp_path: Path) -> None:
    """evo's file_interface.read_tum_trajectory_file: csv rows split on one space, '#' lines
    skipped, exactly 8 entries per row, all float, quaternion x y z w."""
    p = tmp_path / "trajectory.csv"
    write_trajectory_tum(p, T, X, Y, YAW)
    with p.open() as f:
        rows = list(csv.reader((ln for ln in f if not ln.startswith("#")), delimiter=" "))
    mat = np.array(rows).astype(float)
    assert mat.shape == (3, 8)
    quat = mat[:, 4:]
    assert np.allclose(np.linalg.norm(quat, axis=1), 1.0)
    assert np.allclose(2 * np.arctan2(quat[:, 2], quat[:, 3]), YAW)
    assert np.allclose(mat[:, 0], T / 1e9)


def test_round_trip_is_exact_in_time_and_close_in_pose(tmp_path: Path) -> None:
    p = tmp_path / "trajectory.csv"
    write_trajectory_tum(p, T, X, Y, YAW, frame="map")
    back = read_trajectory_tum(p)
    assert back.t_ns.tolist() == T.tolist()
    assert np.allclose(back.x, X, atol=1e-9) and np.allclose(back.y, Y, atol=1e-9)
    assert np.allclose(back.yaw, YAW, atol=1e-8)


def test_stamps_before_the_epoch_round_trip(tmp_path: Path) -> None:
    """A negative stamp is written as its decimal value (−1 ns is "-0.000000001", not the
    floor-divided "-1.999999999") and read back exactly."""
    p = tmp_path / "trajectory.csv"
    t = np.array([-2_000_000_001, -1, 0])
    write_trajectory_tum(p, t, X, Y, YAW)
    assert [ln.split()[0] for ln in p.read_text().splitlines()[1:]] == [
        "-2.000000001", "-0.000000001", "0.000000000"
    ]
    assert read_trajectory_tum(p).t_ns.tolist() == t.tolist()


def test_a_yaw_of_pi_is_one_canonical_quaternion(tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    write_trajectory_tum(a, T[:1], X[:1], Y[:1], [math.pi])
    write_trajectory_tum(b, T[:1], X[:1], Y[:1], [-math.pi])
    assert a.read_bytes() == b.read_bytes()
    assert a.read_text().splitlines()[1].endswith(" 1.000000000 0.000000000")


def test_bad_arrays_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="one length"):
        write_trajectory_tum(tmp_path / "t", T, X[:2], Y, YAW)
    with pytest.raises(ValueError, match="integer nanoseconds"):
        write_trajectory_tum(tmp_path / "t", T / 1e9, X, Y, YAW)
    with pytest.raises(ValueError, match="non-finite"):
        write_trajectory_tum(tmp_path / "t", T, [1.0, np.nan, 2.0], Y, YAW)
    assert not list(tmp_path.iterdir())  # nothing half-written


def test_reading_a_bad_file_names_file_and_line(tmp_path: Path) -> None:
    p = tmp_path / "t.txt"
    p.write_text("# c\n1.0 2 3 0 0 0 0 1\n1.5,2,3,0,0,0,0,1\n")
    with pytest.raises(FormatError, match=r"t\.txt.*line 3.*8 space-separated"):
        read_trajectory_tum(p)
