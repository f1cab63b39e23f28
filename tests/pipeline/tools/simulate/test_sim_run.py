"""Trajectories, whole simulations: timing, yaw, determinism, drift, ground truth files."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from formats.errors import ConfigError, OutputError
from formats.options import MountConfig
from pipeline.tools.simulate import (
    SimOptions,
    load_waypoints,
    load_world,
    run_simulation,
    simulate,
    truth_paths,
    write_simulation,
)
from pipeline.tools.simulate.trajectory import plan_motion, sample_trajectory
from pipeline.tools.simulate.world import World

WORLDS = Path(__file__).resolve().parents[4] / "sample_logs" / "worlds"
BOX = World(
    np.array([[-1, -1, 4, -1], [4, -1, 4, 3], [4, 3, -1, 3], [-1, 3, -1, -1]], dtype=float),
    np.array([[2.0, 2.0, 0.15]]),
)
L_PATH = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 1.5]])


def test_motion_plan_timing_and_turn_in_place() -> None:
    plan = plan_motion(L_PATH, speed=0.3, turn_rate=0.6)
    turn = (math.pi / 2) / 0.6
    np.testing.assert_allclose(plan.t_s, [0.0, 10.0, 10.0 + turn, 15.0 + turn])
    np.testing.assert_allclose(plan.yaw, [0.0, 0.0, math.pi / 2, math.pi / 2])
    # Halfway through the turn the robot is still at the corner, at 45°.
    x, y, yaw = plan.pose_at([10.0 + turn / 2])
    assert (x[0], y[0]) == (3.0, 0.0)
    assert yaw[0] == pytest.approx(math.pi / 4)
    x, y, _ = plan.pose_at([5.0])
    assert (x[0], y[0]) == pytest.approx((1.5, 0.0))


def test_motion_plan_turns_the_short_way_and_skips_repeats() -> None:
    # Heading 170° then −170°: a 20° left turn, not 340° right.
    wp = [[0, 0], [math.cos(math.radians(170)), math.sin(math.radians(170))], [0, 0]]
    wp2 = np.array(wp, dtype=float)
    wp2[2] = wp2[1] + [math.cos(math.radians(-170)), math.sin(math.radians(-170))]
    plan = plan_motion(np.vstack([wp2[:2], wp2[1:2], wp2[2:]]), speed=1.0, turn_rate=1.0)
    assert plan.yaw[-1] - plan.yaw[0] == pytest.approx(math.radians(20))
    assert plan.t_s.shape == (4,)  # the repeated waypoint was skipped
    with pytest.raises(ConfigError, match="all waypoints are the same point"):
        plan_motion([[1, 1], [1, 1]], 1.0, 1.0)


def test_sampled_trajectory_rate_and_wrapped_yaw() -> None:
    plan = plan_motion(L_PATH, speed=0.3, turn_rate=0.6)
    tr = sample_trajectory(plan, 20.0, 5_000_000_000)
    assert tr.t_ns.dtype == np.int64
    assert tr.t_ns[0] == 5_000_000_000
    d = np.diff(tr.t_ns)
    np.testing.assert_array_equal(d[:-1], 50_000_000)
    assert 0 < d[-1] <= 50_000_000  # the end of the plan is included
    assert tr.t_ns[-1] - tr.t_ns[0] == round(plan.duration_s * 1e9)
    assert (tr.x[-1], tr.y[-1]) == pytest.approx((3.0, 1.5))
    assert (tr.yaw >= -math.pi).all() and (tr.yaw < math.pi).all()
    # Driving straight, yaw is the heading of the leg.
    moving = (np.hypot(np.diff(tr.x), np.diff(tr.y)) > 1e-9) & (np.diff(tr.yaw) == 0)
    assert moving.sum() > 250
    heading = np.arctan2(np.diff(tr.y), np.diff(tr.x))[moving]
    np.testing.assert_allclose(heading, tr.yaw[:-1][moving], atol=1e-9)


def _opts(**kw: object) -> SimOptions:
    return SimOptions(**{"sonar_model": "ideal", **kw})  # type: ignore[arg-type]


def test_simulation_shapes_order_and_echoes() -> None:
    sim = simulate(BOX, L_PATH, _opts(seed=1, p_miss=0.0, p_crosstalk=0.0))
    r = sim.ranges
    n = len(r)
    assert n > 0 and r.t_ns.dtype == np.int64 and r.sensor.dtype == np.int32
    np.testing.assert_array_equal(r.sensor[:20], np.arange(20) % 16)
    np.testing.assert_array_equal(r.scan_id, np.arange(n) // 16)
    assert r.t_ns[0] == sim.poses.t_ns[0] and r.t_ns[-1] <= sim.poses.t_ns[-1]
    assert sim.sensor_names == tuple(f"sonar_{i}" for i in range(16))
    # In a closed 5 × 4 m box every sonar sees a wall; noise-free and measured agree to
    # a few σ (σ ≤ 0.01 + 0.01·5 m) where the echo lies inside the limits.
    echo = np.isfinite(r.true_range_m) & (r.true_range_m > 0.1)
    assert echo.mean() > 0.5
    err = r.range_m[echo] - r.true_range_m[echo]
    assert np.abs(err).max() < 5 * 0.06
    assert np.abs(err).mean() < 0.04
    assert ((r.range_m[~echo] == 5.0) | (r.range_m[~echo] == -np.inf)).all()
    # Ranges are float32 values, as Range messages carry them.
    np.testing.assert_array_equal(r.range_m, r.range_m.astype(np.float32))


def test_same_seed_same_arrays_different_seed_differs() -> None:
    a = simulate(BOX, L_PATH, _opts(seed=5, drift_xy=0.02, drift_yaw=0.02))
    b = simulate(BOX, L_PATH, _opts(seed=5, drift_xy=0.02, drift_yaw=0.02))
    c = simulate(BOX, L_PATH, _opts(seed=6, drift_xy=0.02, drift_yaw=0.02))
    for f in ("t_ns", "sensor", "range_m", "true_range_m"):
        np.testing.assert_array_equal(getattr(a.ranges, f), getattr(b.ranges, f))
    for f in ("x", "y", "yaw"):
        np.testing.assert_array_equal(getattr(a.poses, f), getattr(b.poses, f))
    np.testing.assert_array_equal(a.ranges.true_range_m, c.ranges.true_range_m)
    assert not np.array_equal(a.ranges.range_m, c.ranges.range_m)
    assert not np.array_equal(a.poses.x, c.poses.x)


def test_drift_off_logged_equals_true_and_drift_on_departs() -> None:
    sim = simulate(BOX, L_PATH, _opts(seed=2))
    for f in ("t_ns", "x", "y", "yaw"):
        np.testing.assert_array_equal(getattr(sim.poses, f), getattr(sim.true_poses, f))
    drift = simulate(BOX, L_PATH, _opts(seed=2, drift_xy=0.05, drift_yaw=0.05))
    np.testing.assert_array_equal(drift.poses.t_ns, drift.true_poses.t_ns)
    err = np.hypot(drift.poses.x - drift.true_poses.x, drift.poses.y - drift.true_poses.y)
    assert err[0] == 0.0
    assert err[-1] > 1e-3
    # The physics uses the true poses: the readings are the same with or without drift
    # noise-free, and the random draws for the readings come first.
    np.testing.assert_array_equal(sim.ranges.true_range_m, drift.ranges.true_range_m)
    np.testing.assert_array_equal(sim.ranges.range_m, drift.ranges.range_m)


def test_drift_grows_with_distance_on_average() -> None:
    finals = []
    for seed in range(20):
        s = simulate(BOX, L_PATH, _opts(seed=seed, drift_xy=0.05, p_miss=0.0))
        finals.append(math.hypot(s.poses.x[-1] - 3.0, s.poses.y[-1] - 1.5))
    # 4.5 m travelled: per-axis σ ≈ 0.05·√4.5 ≈ 0.11 m; the mean error is of that order.
    assert 0.03 < float(np.mean(finals)) < 0.3


def test_options_are_validated() -> None:
    with pytest.raises(ConfigError, match="'p_miss' must be in \\[0, 1\\]"):
        simulate(BOX, L_PATH, _opts(p_miss=1.5))
    with pytest.raises(ConfigError, match=r"sonar m: beam width 0.0° is not in \(0°, 180°\)"):
        simulate(BOX, L_PATH, _opts(mounts=(MountConfig("m"),)))


def test_write_simulation_truth_files(tmp_path: Path) -> None:
    from formats.writers.nav2_map import load_nav2_map

    sim = simulate(BOX, L_PATH, _opts(seed=1))
    out = tmp_path / "box.csv"
    paths = write_simulation(sim, out, "csv")
    yaml_path, pgm_path, csv_path = truth_paths(out)
    assert paths == [out, yaml_path, pgm_path, csv_path]
    assert yaml_path.name == "box.truth.yaml" and pgm_path.name == "box.truth.pgm"
    with csv_path.open(newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["t", "x", "y", "yaw"]
    assert len(rows) - 1 == len(sim.true_poses)
    t0 = sim.true_poses.t_ns[0]
    assert rows[1][0] == f"{t0 // 10**9}.{t0 % 10**9:09d}"
    assert float(rows[-1][1]) == sim.true_poses.x[-1]
    m = load_nav2_map(yaml_path)
    # The wall at x = 4 is occupied, the middle of the box free.
    g = m.grid
    col = int((4.0 - g.origin_x) // g.resolution)
    row = int((1.0 - g.origin_y) // g.resolution)
    assert m.classes[row, col] == 1
    assert m.classes[row, col - 10] == 0
    with pytest.raises(OutputError, match="exists already, not overwriting"):
        write_simulation(sim, tmp_path / "box.bag", "ros1")  # box.truth.* exist already
    assert not (tmp_path / "box.bag").exists()


def test_run_simulation_with_shipped_world(tmp_path: Path) -> None:
    opts = SimOptions(sonar_model="ideal", seed=3)
    paths = run_simulation(WORLDS / "corridor.toml", tmp_path / "c.mcap", "mcap", options=opts)
    assert [p.name for p in paths] == ["c.mcap", "c.truth.yaml", "c.truth.pgm", "c.truth.csv"]
    assert all(p.is_file() for p in paths)
    # Same run straight from the API: the same readings.
    sim = simulate(
        load_world(WORLDS / "corridor.toml"),
        load_waypoints(WORLDS / "corridor.waypoints.csv"),
        opts,
    )
    from mcap.reader import make_reader

    with paths[0].open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    counts = summary.statistics.channel_message_counts
    topics = {ch.topic: counts[cid] for cid, ch in summary.channels.items()}
    assert topics == {"/sonar": len(sim.ranges), "/odom": len(sim.poses), "/tf_static": 1}
    # 2 × 13 m at 0.3 m/s plus a 180° turn at 0.6 rad/s.
    duration = (sim.poses.t_ns[-1] - sim.poses.t_ns[0]) / 1e9
    assert duration == pytest.approx(26 / 0.3 + math.pi / 0.6, abs=1e-6)
