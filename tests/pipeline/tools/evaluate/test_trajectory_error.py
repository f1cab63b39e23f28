"""ATE and RPE (pipeline.tools.trajectory_error) against hand-computed cases, and the
trajectory CSV they read (formats.writers.trajectory_csv)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from formats.errors import ConfigError, FormatError, InputError
from formats.writers.trajectory_csv import read_trajectory_csv, write_trajectory_csv
from formats.writers.trajectory_tum import Trajectory
from pipeline.tools.trajectory_error import align_se2, rpe_pairs, trajectory_error

NS = 1_000_000_000


def poses(x: list[float], y: list[float], yaw: list[float] | None = None,
          t_s: list[float] | None = None) -> Trajectory:
    n = len(x)
    t = np.arange(n) if t_s is None else np.asarray(t_s)
    return Trajectory((np.asarray(t) * NS).astype(np.int64), np.asarray(x, float),
                   np.asarray(y, float), np.zeros(n) if yaw is None else np.asarray(yaw, float))


def test_a_rigidly_moved_estimate_has_zero_ate_and_rpe() -> None:
    truth = poses([0, 1, 2, 3, 3], [0, 0, 0, 0, 1], [0, 0, 0, math.pi / 2, math.pi / 2])
    th, tx, ty = math.radians(30), 5.0, -2.0
    c, s = math.cos(th), math.sin(th)
    est = Trajectory(truth.t_ns, c * truth.x - s * truth.y + tx, s * truth.x + c * truth.y + ty,
                  truth.yaw + th)
    e = trajectory_error(est, truth)
    assert e.ate_rmse_m == pytest.approx(0.0, abs=1e-12)
    assert e.ate_max_m == pytest.approx(0.0, abs=1e-12)
    assert e.rpe_trans_rmse_m == pytest.approx(0.0, abs=1e-12)
    assert e.rpe_rot_rmse_deg == pytest.approx(0.0, abs=1e-9)
    # The alignment undoes the motion: rotation -30 degrees.
    assert math.degrees(e.alignment[2]) == pytest.approx(-30.0)
    assert e.poses_compared == 5


def test_ate_of_one_displaced_pose_after_alignment() -> None:
    # Truth on a square's corners; the estimate moves one corner 0.4 m out. Hand-computed:
    # the best rigid fit translates by 0.1 m (rotation 0 by symmetry of the offsets'
    # cross products) so the errors are 0.3, 0.1, 0.1, 0.1.
    truth = poses([0, 1, 1, 0], [0, 0, 1, 1])
    est = poses([0, 1, 1.4, 0], [0, 0, 1, 1])
    tx, ty, th = align_se2(est.x, est.y, truth.x, truth.y)
    e = trajectory_error(est, truth)
    errs = np.array([0.1, 0.1, 0.3, 0.1])
    # Rotation is not exactly 0 here: check against the closed form instead.
    c, s = math.cos(th), math.sin(th)
    d = np.hypot(c * est.x - s * est.y + tx - truth.x, s * est.x + c * est.y + ty - truth.y)
    assert e.ate_rmse_m == pytest.approx(math.sqrt(np.mean(d**2)))
    assert e.ate_rmse_m < math.sqrt(np.mean(errs**2)) + 1e-12  # never worse than a pure shift
    assert e.ate_max_m == pytest.approx(d.max())


def test_ate_of_a_pure_offset_pair_is_hand_computed() -> None:
    # Two poses: the estimate's second one is 0.2 m too far along x. Aligning (rotation 0 by
    # symmetry, translation -0.1 m) leaves errors 0.1 m and 0.1 m.
    e = trajectory_error(poses([0.0, 1.2], [0.0, 0.0]), poses([0.0, 1.0], [0.0, 0.0]))
    assert e.ate_rmse_m == pytest.approx(0.1)
    assert e.ate_mean_m == pytest.approx(0.1)
    assert e.alignment[2] == pytest.approx(0.0, abs=1e-12)


def test_rpe_per_metre_of_a_scale_error() -> None:
    truth = poses([0, 0.5, 1, 1.5, 2, 2.5, 3], [0] * 7)
    est = poses([1.1 * v for v in truth.x.tolist()], [0] * 7)
    i, j = rpe_pairs(truth, 1.0, "m")
    assert i.tolist() == [0, 2, 4] and j.tolist() == [2, 4, 6]
    e = trajectory_error(est, truth, rpe_delta=1.0, rpe_unit="m")
    assert e.rpe_pairs == 3
    assert e.rpe_trans_rmse_m == pytest.approx(0.1)
    assert e.rpe_rot_mean_deg == pytest.approx(0.0)


def test_rpe_rotation_error_and_frames_unit() -> None:
    truth = poses([0, 1, 2], [0, 0, 0], [0, 0, 0])
    est = poses([0, 1, 2], [0, 0, 0], [0, math.radians(2), math.radians(4)])
    e = trajectory_error(est, truth, rpe_delta=1, rpe_unit="frames")
    assert e.rpe_pairs == 2
    assert e.rpe_rot_rmse_deg == pytest.approx(2.0)
    # Pair (0, 1): no translation error; pair (1, 2): the estimate's pose 1 is turned by 2
    # degrees, so the 1 m step seen from it is off by 2·sin(1°).
    assert e.rpe_trans_mean_m == pytest.approx(math.sin(math.radians(1.0)))


def test_truth_is_interpolated_at_the_estimate_stamps() -> None:
    truth = poses([0.0, 2.0, 4.0], [0.0, 0.0, 0.0], t_s=[0, 2, 4])
    est = poses([1.0, 3.0], [0.0, 0.0], t_s=[1, 3])  # exactly on the truth
    e = trajectory_error(est, truth)
    assert e.poses_compared == 2 and e.ate_rmse_m == pytest.approx(0.0, abs=1e-12)
    late = poses([5.0, 6.0], [0.0, 0.0], t_s=[5, 6])
    with pytest.raises(InputError, match="time span"):
        trajectory_error(late, truth)
    with pytest.raises(ConfigError, match="delta"):
        trajectory_error(est, truth, rpe_delta=1.5, rpe_unit="frames")


def test_trajectory_csv_round_trip_and_errors(tmp_path: Path) -> None:
    p = tmp_path / "t.csv"
    t = np.array([1_700_000_000_000_000_001, 1_700_000_000_500_000_000], np.int64)
    x, y, yaw = np.array([0.1, 1 / 3]), np.array([-2.0, 1e-17]), np.array([3.0, -0.5])
    write_trajectory_csv(p, t, x, y, yaw)
    assert p.read_text().splitlines()[:2] == ["t,x,y,yaw", "1700000000.000000001,0.1,-2.0,3.0"]
    back = read_trajectory_csv(p)
    assert np.array_equal(back.t_ns, t) and np.array_equal(back.x, x)
    assert np.array_equal(back.y, y) and np.array_equal(back.yaw, yaw)
    p.write_text("t,x,y,yaw\n1.0,0,0,0\n0.5,1,1,0\n")
    with pytest.raises(FormatError, match="line 3: stamps must increase"):
        read_trajectory_csv(p)
    p.write_text("t,x,y\n1.0,0,0\n")
    with pytest.raises(FormatError, match="no yaw column"):
        read_trajectory_csv(p)
    p.write_text("1.0,0,0,zero\n")
    with pytest.raises(FormatError, match="line 1"):
        read_trajectory_csv(p)
    with pytest.raises(InputError, match="not found"):
        read_trajectory_csv(tmp_path / "missing.csv")
