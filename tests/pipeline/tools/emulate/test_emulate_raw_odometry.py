"""emulate --raw-odometry: the laser log's own wheel odometry as the pose track (real drift),
the corrected scan poses as the truth."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from emulate_helpers import INTEL, NS, laser_log

from formats.carmen import CarmenOdom
from formats.contract import PoseBatch
from formats.errors import ConfigError, InputError
from formats.laser_log import carmen_odometry
from formats.presets import PRESETS
from formats.writers.trajectory_csv import read_trajectory
from pipeline.drift import DriftModel
from pipeline.tools.emulate import EmulateOptions, emulate, load_laser_log, ring_from_mounts
from pipeline.tools.emulate.run import run_emulation

REPO = Path(__file__).resolve().parents[4]
OREBRO = REPO / "sample_logs" / "radish" / "orebro-corrected.log.gz"


def odom(t_s: list[float], x: list[float]) -> CarmenOdom:
    n = len(t_s)
    z = np.zeros(n)
    return CarmenOdom((np.asarray(t_s) * NS).astype(np.int64), np.asarray(x, float), z.copy(),
                      z.copy(), z.copy(), z.copy())


def test_carmen_odometry_sorted_one_pose_per_stamp_or_none() -> None:
    o = carmen_odometry(odom([2.0, 1.0, 1.0, 3.0], [20.0, 10.0, 11.0, 30.0]), "base_link")
    assert o is not None
    assert o.t_ns.tolist() == [NS, 2 * NS, 3 * NS]
    assert o.x.tolist() == [10.0, 20.0, 30.0]  # the first line of a repeated stamp
    assert (o.parent_frame, o.child_frame) == ("odom", "base_link")
    assert carmen_odometry(odom([0.0, 0.0, 0.0], [0.0, 1.0, 2.0]), "base_link") is None
    assert carmen_odometry(odom([1.0], [0.0]), "base_link") is None


def straight_scans() -> tuple[object, list[tuple[float, float, float]]]:
    """Five scans 1 s apart along +y from (2, 1) (the truth), a wall ahead."""
    poses = [(2.0, 1.0 + k, math.pi / 2) for k in range(5)]
    log = laser_log(np.full((5, 3), 4.0), [-10, 0, 10], poses=poses)
    return log, poses


def test_the_odometry_is_moved_to_start_at_the_first_scan_and_the_scans_become_truth() -> None:
    log, poses = straight_scans()
    em = emulate(log, ring_from_mounts(PRESETS["pioneer-p3dx"][3:5]))
    # Odometry in its own frame: along +x from the origin, 10 % too long, 0.5 s before the
    # first scan to 0.5 s after the last.
    t = (np.arange(0.5, 6.0, 0.5) * NS).astype(np.int64)
    along = 1.1 * (t / NS - 1.0)
    raw = PoseBatch(t, along, np.zeros(t.shape), np.zeros(t.shape), "odom", "base_link")
    out = em.with_raw_odometry(raw)
    p = out.content.poses
    # The scans span 1…5 s: the odometry is cut to the poses that cover it.
    assert p.t_ns.tolist() == t[1:10].tolist() and p.t_ns[0] == NS and p.t_ns[-1] == 5 * NS
    # At the first scan (t = 1 s) the odometry is at the first true pose, heading alike.
    assert (p.x[0], p.y[0], p.yaw[0]) == pytest.approx((2.0, 1.0, math.pi / 2))
    # From there it drifts: 10 % long along the true direction of travel.
    assert (p.x[-1], p.y[-1]) == pytest.approx((2.0, 1.0 + 4.4))
    assert p.parent_frame == "odom"
    assert out.truth is not None and out.truth.y.tolist() == [q[1] for q in poses]
    assert "raw wheel odometry" in out.notes[-1] and "0.40 m at most" in out.notes[-1]


def test_odometry_that_does_not_cover_the_scans_is_refused() -> None:
    log, _ = straight_scans()
    em = emulate(log, ring_from_mounts(PRESETS["pioneer-p3dx"][3:5]))
    t = (np.arange(2.0, 6.0, 0.5) * NS).astype(np.int64)
    late = PoseBatch(t, t / NS, 0 * t / NS, 0 * t / NS, "odom", "base_link")
    with pytest.raises(InputError, match=r"odometry \(2.000…5.500 s\) does not cover its scans "
                                         r"\(1.000…5.000 s\)"):
        em.with_raw_odometry(late)


def test_intel_raw_odometry_drifts_from_the_corrected_poses(tmp_path: Path) -> None:
    opts = EmulateOptions(sonar_model="ideal", max_scans=200, raw_odometry=True)
    res = run_emulation(INTEL, tmp_path / "odo.mcap", "mcap", options=opts)
    note = next(n for n in res.notes if n.startswith("poses: the log's raw wheel odometry"))
    truth = read_trajectory(tmp_path / "odo.truth.csv")
    laser = load_laser_log(INTEL, max_scans=200)
    assert len(truth) == 200 and truth.x.tolist() == laser.x.tolist()  # truth = corrected
    mean_m = float(note.split(" m from the corrected")[0].rsplit(" ", 1)[1])
    assert 0.05 < mean_m < 2.0  # real drift: not zero, not a broken frame


def test_raw_odometry_refusals(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="raw odometry and a drift model are exclusive"):
        run_emulation(INTEL, tmp_path / "a.mcap", "mcap", options=EmulateOptions(sonar_model="ideal",
            raw_odometry=True, drift=DriftModel(scale_error=0.03)))
    with pytest.raises(InputError, match=r"orebro-corrected\.log\.gz: the log has no raw odometry"):
        run_emulation(OREBRO, tmp_path / "b.mcap", "mcap",
                      options=EmulateOptions(sonar_model="ideal", raw_odometry=True))
    assert not list(tmp_path.iterdir())  # nothing half-written


def test_sorting_scans_keeps_the_odometry() -> None:
    from formats.laser_log import sorted_by_time

    log, _ = straight_scans()
    o = PoseBatch(np.array([0, 9 * NS]), np.zeros(2), np.zeros(2), np.zeros(2), "odom", "b")
    shuffled = dataclasses.replace(log, t_ns=log.t_ns[::-1].copy(), odometry=o)
    assert sorted_by_time(shuffled).odometry is o
