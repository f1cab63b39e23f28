"""LaserScan bags (ROS 1 and ROS 2, written with rosbags): scans, odometry poses, mount."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from emulate_helpers import NS, Msgs, wall_ranges, write_bag

from formats.errors import TopicError
from formats.options import InputConfig
from formats.presets import PRESETS
from pipeline.config import Config
from pipeline.tools.emulate import emulate, load_laser_log, ring_from_mounts

ODOM = "nav_msgs/msg/Odometry"
SCAN = "sensor_msgs/msg/LaserScan"
TF = "tf2_msgs/msg/TFMessage"
INC = math.radians(0.5)
ANGLES_DEG = np.degrees(-math.pi / 2 + INC * np.arange(361))
WALL_X = 3.0  # world x of a wall facing the robot
LASER_X = 0.2  # laser mount ahead of the base


def robot_x(t_s: float) -> float:
    return 0.1 * t_s


def laser_bag(
    path: Path,
    kind: str = "ros1",
    *,
    with_tf: bool = True,
    scan_topics: tuple[str, ...] = ("/scan",),
) -> Path:
    m = Msgs(kind)
    msgs: list[tuple[str, str, int, Any]] = []
    if with_tf:
        msgs.append(
            ("/tf_static", TF, NS // 2, m.tf_static(NS // 2, "base_link", "laser", LASER_X, 0.0))
        )
    for i in range(12):  # odometry 0.5 … 6.0 s
        t = (i + 1) * NS // 2
        msgs.append(("/odom", ODOM, t, m.odom(t, robot_x(t / NS), 0.0, 0.0)))
    for k in range(1, 6):  # scans at 1.25 … 5.25 s, between odometry stamps
        t = k * NS + NS // 4
        lx = robot_x(t / NS) + LASER_X
        r = wall_ranges(WALL_X, ANGLES_DEG, mount_x=lx, far=30.0)
        for topic in scan_topics:
            msgs.append((topic, SCAN, t, m.scan(t, r, -math.pi / 2, INC)))
    msgs.sort(key=lambda x: x[2])
    return write_bag(path, kind, msgs)


@pytest.mark.parametrize(("kind", "name"), [("ros1", "laser.bag"), ("ros2", "laser_bag")])
def test_laserscan_poses_and_mount(tmp_path: Path, kind: str, name: str) -> None:
    log = load_laser_log(laser_bag(tmp_path / name, kind))
    assert len(log) == 5
    assert log.source_format == kind
    assert log.t_ns.tolist() == [k * NS + NS // 4 for k in range(1, 6)]
    assert log.ranges.shape == (5, 361)
    np.testing.assert_allclose(
        log.angles[0, [0, 180, 360]], [-math.pi / 2, 0.0, math.pi / 2], atol=1e-6
    )
    # Odometry interpolated at the scan stamps.
    np.testing.assert_allclose(log.x, [robot_x(k + 0.25) for k in range(1, 6)], atol=1e-9)
    assert (log.parent_frame, log.child_frame) == ("odom", "base_link")
    mt = log.laser_mount
    assert (mt.x, mt.y, mt.yaw) == pytest.approx((LASER_X, 0.0, 0.0))
    assert log.range_max.tolist() == [30.0] * 5
    em = emulate(log, ring_from_mounts(PRESETS["pioneer-p3dx"]))
    # The laser sits 0.2 m ahead of the base: the axes of the ±90° sonars (at x = 0.069 m)
    # pass behind it, outside its 180° view, so only sonar_1 … sonar_6 are emitted.
    assert em.ring.names == tuple(f"sonar_{i}" for i in range(1, 7))
    want = [WALL_X - robot_x(k + 0.25) - 0.166 for k in range(1, 6)]
    np.testing.assert_allclose(em.ranges[:, 2], want, atol=3e-3)  # sonar_3; 0.5° beams


def test_no_static_transform_puts_the_laser_at_the_base(tmp_path: Path) -> None:
    log = load_laser_log(laser_bag(tmp_path / "laser.bag", with_tf=False), max_scans=2)
    assert len(log) == 2
    assert (log.laser_mount.x, log.laser_mount.y) == (0.0, 0.0)
    assert any("laser at the base origin" in n for n in log.notes)


def test_topic_errors(tmp_path: Path) -> None:
    two = laser_bag(tmp_path / "two.bag", scan_topics=("/scan", "/scan2"))
    with pytest.raises(TopicError, match=r"several LaserScan topics \(/scan, /scan2\)"):
        load_laser_log(two)
    assert len(load_laser_log(two, laser_topic="/scan2")) == 5
    with pytest.raises(TopicError, match=r"laser topic /nope is not a sensor_msgs/LaserScan topic"):
        load_laser_log(two, laser_topic="/nope")
    odom = Msgs("ros1").odom(NS, 0.0, 0.0, 0.0)
    odom_only = write_bag(tmp_path / "odom.bag", "ros1", [("/odom", ODOM, NS, odom)])
    with pytest.raises(
        TopicError,
        match=r"odom\.bag: no sensor_msgs/LaserScan topic; "
        r"the log contains: /odom:nav_msgs/msg/Odometry",
    ):
        load_laser_log(odom_only)


def test_pose_topic_from_config_must_exist(tmp_path: Path) -> None:
    cfg = Config(input=InputConfig(pose_topic="/missing"))
    with pytest.raises(TopicError, match=r"pose topic /missing is not in the log"):
        load_laser_log(laser_bag(tmp_path / "laser.bag"), cfg)
