"""CARMEN log parsing: values, beam angles, PARAMs, gzip and errors with line numbers."""

from __future__ import annotations

import gzip
import math
from pathlib import Path

import numpy as np
import pytest

from formats.carmen import beam_angles, looks_like_carmen, read_carmen
from formats.errors import FormatError


def flaser(ranges: list[float], pose: tuple[float, float, float], t: str) -> str:
    r = " ".join(f"{v:g}" for v in ranges)
    x, y, a = pose
    return f"FLASER {len(ranges)} {r} {x} {y} {a} 9 9 9 {t} host {t}"


def write(tmp_path: Path, lines: list[str], name: str = "log.log") -> Path:
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


LINES = [
    "# message formats defined: PARAM SYNC ODOM FLASER",
    "PARAM robot_frontlaser_offset 0.25 nohost 0",
    "ODOM 0.5 -0.25 0.1 0.3 0.05 0 1.5 host 1.5",
    flaser([1.0] * 4, (1.0, 2.0, 0.5), "2.000001"),
    "NEFF 12.5",
    flaser([2.0, 3.0, 81.83, 0.5], (1.5, 2.5, -0.5), "1234567890.123456789"),
]


def test_flaser_values_poses_and_exact_stamps(tmp_path: Path) -> None:
    log = read_carmen(write(tmp_path, LINES))
    las = log.laser
    assert len(las) == 2
    assert las.ranges.shape == (2, 4)
    np.testing.assert_array_equal(las.ranges[1], [2.0, 3.0, 81.83, 0.5])
    np.testing.assert_array_equal(las.x, [1.0, 1.5])
    np.testing.assert_array_equal(las.yaw, [0.5, -0.5])
    np.testing.assert_array_equal(las.odom_x, [9.0, 9.0])
    # Decimal seconds become exact integer nanoseconds (no float rounding).
    assert las.t_ns.tolist() == [2_000_001_000, 1_234_567_890_123_456_789]
    assert las.line.tolist() == [4, 6]
    assert las.max_range == pytest.approx(81.83)
    assert log.laser_mount.x == 0.25
    assert log.params["robot_frontlaser_offset"] == "0.25"
    assert log.skipped == {"NEFF": 1}
    assert len(log.odom) == 1
    assert (log.odom.x[0], log.odom.y[0], log.odom.yaw[0]) == (0.5, -0.25, 0.1)
    assert (log.odom.tv[0], log.odom.rv[0]) == (0.3, 0.05)
    assert log.odom.t_ns.tolist() == [1_500_000_000]


def test_beam_angles_180_and_361() -> None:
    a = beam_angles(180, math.pi)
    assert a.shape == (180,)
    np.testing.assert_allclose(np.degrees(a[[0, 1, 90, 179]]), [-90.0, -89.0, 0.0, 89.0])
    b = beam_angles(361, math.pi)
    np.testing.assert_allclose(np.degrees(b[[0, 180, 360]]), [-90.0, 0.0, 90.0], atol=1e-12)


def test_fov_and_max_range_params(tmp_path: Path) -> None:
    lines = [
        "PARAM laser_front_laser_fov 100 nohost 0",
        "PARAM robot_front_laser_max 8.0 nohost 0",
        flaser([1.0] * 100, (0, 0, 0), "1.0"),
    ]
    las = read_carmen(write(tmp_path, lines)).laser
    assert las.fov_rad == pytest.approx(math.radians(100))
    assert math.degrees(las.angles[0]) == pytest.approx(-50.0)
    assert math.degrees(las.angles[1] - las.angles[0]) == pytest.approx(1.0)
    assert las.max_range == 8.0
    # An explicit override beats the PARAM.
    assert read_carmen(tmp_path / "log.log", laser_max_range=4.0).laser.max_range == 4.0


@pytest.mark.parametrize(("value", "fov_deg"), [("100", 100.0), ("180", 180.0),
                                             ("3.14159", 179.9998), ("6.2832", 360.0)])
def test_a_field_of_view_up_to_two_pi_is_radians(tmp_path: Path, value: str,
                                                 fov_deg: float) -> None:
    # MIT CSAIL's log: "PARAM laser_front_laser_fov 3.14159" for 361 beams at 0.5°.
    lines = [f"PARAM laser_front_laser_fov {value} nohost 0", flaser([1.0] * 361, (0, 0, 0), "1.0")]
    las = read_carmen(write(tmp_path, lines)).laser
    assert math.degrees(las.fov_rad) == pytest.approx(fov_deg, abs=1e-3)
    assert math.degrees(las.angles[0]) == pytest.approx(-fov_deg / 2, abs=1e-3)


@pytest.mark.parametrize("value", ["0", "-90", "400"])
def test_a_field_of_view_out_of_range_names_the_param(tmp_path: Path, value: str) -> None:
    lines = [f"PARAM laser_front_laser_fov {value} nohost 0", flaser([1.0] * 10, (0, 0, 0), "1.0")]
    with pytest.raises(FormatError, match=rf"log.log: laser field of view {value} "
                                          r"\(PARAM laser_front_laser_fov\) is not in"):
        read_carmen(write(tmp_path, lines))


def test_gzip_and_max_scans(tmp_path: Path) -> None:
    p = tmp_path / "log.log.gz"
    p.write_bytes(gzip.compress(("\n".join(LINES) + "\n").encode()))
    assert looks_like_carmen(p)
    log = read_carmen(p, max_scans=1)
    assert len(log.laser) == 1
    assert log.laser.x.tolist() == [1.0]


def test_wrong_field_count_names_the_line(tmp_path: Path) -> None:
    bad = [*LINES[:4], "FLASER 4 1 1 1 1 0 0 0 0 0 0 5.0 host"]  # logger timestamp missing
    with pytest.raises(
        FormatError, match=r"log\.log: line 5: FLASER has 14 fields, expected 15 for 4 beams"
    ):
        read_carmen(write(tmp_path, bad))


def test_non_numeric_range_names_the_line(tmp_path: Path) -> None:
    bad = [*LINES[:4], "", "FLASER 4 1.0 abc 1 1 0 0 0 0 0 0 3.0 host 3.0"]
    with pytest.raises(FormatError, match=r"line 6: FLASER field 'abc' is not a number"):
        read_carmen(write(tmp_path, bad))


def test_beam_count_change_and_bad_timestamp(tmp_path: Path) -> None:
    bad = [flaser([1.0] * 3, (0, 0, 0), "1.0"), flaser([1.0] * 4, (0, 0, 0), "2.0")]
    with pytest.raises(FormatError, match=r"line 2: FLASER has 4 beams, earlier scans have 3"):
        read_carmen(write(tmp_path, bad))
    with pytest.raises(FormatError, match=r"line 1: timestamp: expected a time, found 'soon'"):
        read_carmen(write(tmp_path, [flaser([1.0], (0, 0, 0), "soon")], "t.log"))


def test_odom_field_count(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match=r"line 2: ODOM has 9 fields, expected 10"):
        read_carmen(write(tmp_path, ["PARAM a 1 h 0", "ODOM 1 2 3 4 5 6 7.0 host"]))


def test_not_carmen_and_corrupt_gzip(tmp_path: Path) -> None:
    p = write(tmp_path, ["t,x,y", "1,2,3"], "table.csv")
    assert not looks_like_carmen(p)
    with pytest.raises(FormatError, match=r"line 1: not a CARMEN log \(first message is 't,x,y'\)"):
        read_carmen(p)
    gz = tmp_path / "cut.log.gz"
    gz.write_bytes(gzip.compress(b"FLASER 1 1.0 0 0 0 0 0 0 1.0 h 1.0\n" * 50)[:40])
    with pytest.raises(FormatError, match=r"cut\.log\.gz: corrupt or truncated gzip data"):
        read_carmen(gz)
    with pytest.raises(FormatError, match=r"no such file"):
        read_carmen(tmp_path / "missing.log")
    empty = write(tmp_path, ["# only a comment"], "empty.log")
    with pytest.raises(FormatError, match=r"no CARMEN messages"):
        read_carmen(empty)
