"""formats.laser_log: a CARMEN log's scans for emulation, and logs that carry no time."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from formats.laser_log import UNSTAMPED_SCAN_PERIOD_NS, read_carmen_laser_log, stamps_order_scans

NS = 1_000_000_000


def carmen(tmp_path: Path, stamps: list[str], odom_stamps: list[str]) -> Path:
    lines = [f"ODOM {k * 0.1} 0 0 0 0 0 {t} host {t}" for k, t in enumerate(odom_stamps)]
    lines += [f"FLASER 3 1 2 3 {k * 0.5} 0 0 0 0 0 {t} host {t}" for k, t in enumerate(stamps)]
    p = tmp_path / "log.log"
    p.write_text("\n".join(lines) + "\n")
    return p


@pytest.mark.parametrize(("diffs", "ordered"), [
    ([1, 1, 1, 1], True),
    ([1, -1, 1, 1, 1, 0, 1], True),  # the Intel lab: a few scans out of order
    ([0, 0, 1, 0, 0], False),  # six significant digits: most stamps repeat
    ([0, 0, 0], False),  # every stamp the same
])
def test_stamps_order_the_scans_when_most_of_them_increase(diffs: list[int],
                                                           ordered: bool) -> None:
    t = np.concatenate([[0], np.cumsum(diffs)]).astype(np.int64)
    assert stamps_order_scans(t) is ordered


def test_a_log_whose_stamps_repeat_is_stamped_in_log_order(tmp_path: Path) -> None:
    # MIT CSAIL's corrected log writes its stamps as 1.13486e+09: 404 of 406 repeat.
    stamps = ["1.13486e+09"] * 4 + ["1.13487e+09"] * 2
    log = read_carmen_laser_log(carmen(tmp_path, stamps, stamps), "base_link", None, None)
    assert log.t_ns.tolist() == [k * UNSTAMPED_SCAN_PERIOD_NS for k in range(6)]
    assert log.x.tolist() == [0.0, 0.5, 1.0, 1.5, 2.0, 2.5]  # the scans in log order
    assert "4 of 5 FLASER stamps do not increase (the log carries no time)" in log.notes[-1]
    assert log.odometry is None  # its ODOM lines have no clock in common with the scans


def test_a_timeless_log_starting_below_zero_is_stamped_from_zero(tmp_path: Path) -> None:
    # The Infinite Corridor: four stamps from -0.446 s down, then 4.29497e+09 on every scan.
    stamps = ["-0.445999", "-0.913", "4.29497e+09", "4.29497e+09", "4.29497e+09"]
    log = read_carmen_laser_log(carmen(tmp_path, stamps, []), "base_link", None, None)
    assert log.t_ns.tolist() == [k * UNSTAMPED_SCAN_PERIOD_NS for k in range(5)]


def test_a_log_with_time_keeps_its_stamps_and_odometry(tmp_path: Path) -> None:
    stamps = ["10.0", "10.5", "10.4", "11.0", "11.5"]
    log = read_carmen_laser_log(carmen(tmp_path, stamps, ["9.9", "10.2", "11.6"]), "base_link",
                                None, None)
    assert log.t_ns.tolist() == [int(float(s) * NS) for s in stamps]
    assert log.odometry is not None and len(log.odometry.t_ns) == 3
