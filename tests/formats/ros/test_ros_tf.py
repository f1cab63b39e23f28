"""formats/ros/tf.py: planar tf chains and static mounts (pure functions)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest

from formats.ros import tf as tflib
from formats.ros.columns import TransformColumns


def _cols(rows: Sequence[tuple[int, str, str, float, float, float]]) -> TransformColumns:
    """TransformColumns from (t_ns, parent, child, x, y, yaw) rows."""
    frames: list[str] = []
    for _t, p, c, *_ in rows:
        for f in (p, c):
            if f not in frames:
                frames.append(f)
    yaw = np.array([r[5] for r in rows])
    return TransformColumns(
        msg_index=np.arange(len(rows), dtype=np.int64),
        stamp_ns=np.array([r[0] for r in rows], np.int64),
        parent=np.array([frames.index(r[1]) for r in rows], np.int32),
        child=np.array([frames.index(r[2]) for r in rows], np.int32),
        frames=frames,
        x=np.array([r[3] for r in rows], float),
        y=np.array([r[4] for r in rows], float),
        z=np.full(len(rows), 0.2),
        qx=np.zeros(len(rows)),
        qy=np.zeros(len(rows)),
        qz=np.sin(yaw / 2),
        qw=np.cos(yaw / 2),
    )


def test_yaw_from_quaternion() -> None:
    yaw = np.array([0.0, 0.3, -2.0, 3.0])
    got = tflib.yaw_from_quaternion(np.zeros(4), np.zeros(4), np.sin(yaw / 2), np.cos(yaw / 2))
    np.testing.assert_allclose(got, yaw, atol=1e-12)
    # A pure roll of 90 degrees has no yaw.
    roll = tflib.yaw_from_quaternion(
        np.array([math.sin(math.pi / 4)]),
        np.zeros(1),
        np.zeros(1),
        np.array([math.cos(math.pi / 4)]),
    )
    assert roll[0] == pytest.approx(0.0, abs=1e-12)


def test_compose_and_invert() -> None:
    a = (np.array([1.0]), np.array([2.0]), np.array([math.pi / 2]))
    b = (np.array([1.0]), np.array([0.0]), np.array([math.pi / 2]))
    x, y, yaw = tflib.compose(a, b)
    assert (x[0], y[0], yaw[0]) == pytest.approx((1.0, 3.0, -math.pi))  # wrapped to [-pi, pi)
    ix, iy, iyaw = tflib.compose(tflib.invert(a), a)
    assert (ix[0], iy[0], iyaw[0]) == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)


def test_interpolation_takes_the_short_way_round() -> None:
    link = tflib.Link(
        "odom",
        "base_link",
        np.array([0, 10], np.int64),
        np.array([0.0, 1.0]),
        np.array([0.0, 2.0]),
        np.array([3.0, -3.0]),
        static=False,
    )
    x, y, yaw = tflib.interpolate(link, np.array([-5, 5, 20], np.int64))
    assert x.tolist() == [0.0, 0.5, 1.0]  # held outside the samples
    assert y.tolist() == [0.0, 1.0, 2.0]
    # 3.0 → −3.0 the short way passes through π, not through 0.
    assert abs(yaw[1]) == pytest.approx(math.pi)


def test_build_links_marks_static_and_constant_links() -> None:
    moving = _cols([(t, "odom", "base_link", 0.1 * t, 0.0, 0.0) for t in range(5)])
    constant = _cols([(t, "base_link", "sonar_back", -0.2, 0.0, math.pi) for t in range(5)])
    static = _cols([(0, "base_link", "sonar_front", 0.2, 0.0, 0.0)])
    links = tflib.build_links([(moving, False), (constant, False), (static, True)])
    assert sorted(links) == ["base_link", "sonar_back", "sonar_front"]
    assert not links["base_link"].static and len(links["base_link"]) == 5
    assert links["sonar_back"].static and len(links["sonar_back"]) == 1
    assert links["sonar_front"].static


def test_build_links_keeps_last_sample_of_a_repeated_stamp() -> None:
    links = tflib.build_links(
        [
            (
                _cols(
                    [
                        (0, "odom", "b", 0.0, 0, 0),
                        (5, "odom", "b", 1.0, 0, 0),
                        (5, "odom", "b", 2.0, 0, 0),
                    ]
                ),
                False,
            )
        ]
    )
    assert links["b"].t_ns.tolist() == [0, 5]
    assert links["b"].x.tolist() == [0.0, 2.0]


def test_root_prefers_map_then_odom() -> None:
    rows = [
        (0, "map", "odom", 0, 0, 0),
        (1, "map", "odom", 1, 0, 0),
        (0, "odom", "base_link", 0, 0, 0),
        (1, "odom", "base_link", 1, 0, 0),
        (0, "world", "map", 0, 0, 0),
    ]
    links = tflib.build_links([(_cols(rows), False)])
    assert tflib.choose_root(links, "base_link") == "map"
    no_map = tflib.build_links(
        [(_cols([r for r in rows if r[1] != "map" and r[2] != "map"]), False)]
    )
    assert tflib.choose_root(no_map, "base_link") == "odom"
    other = tflib.build_links(
        [(_cols([(0, "world", "robot", 0, 0, 0), (0, "robot", "base_link", 0, 0, 0)]), False)]
    )
    assert tflib.choose_root(other, "base_link") == "world"


def test_chain_poses_at_the_fastest_link_stamps() -> None:
    ms = 1_000_000
    # map→odom at 1 Hz (0..3 s), odom→base_link at 10 Hz (0..4 s), base_link→laser static.
    slow = [(k * 1000 * ms, "map", "odom", 1.0 + k, 0.5, 0.1 * k) for k in range(4)]
    fast = [(k * 100 * ms, "odom", "base_link", 0.1 * k, 0.0, 0.05 * k) for k in range(41)]
    links = tflib.build_links([(_cols(slow), False), (_cols(fast), False)])
    pb = tflib.pose_batch(links, "base_link")
    assert (pb.parent_frame, pb.child_frame) == ("map", "base_link")
    # Only inside the span both moving links cover: 0..3 s, 31 stamps.
    assert pb.t_ns.tolist() == [k * 100 * ms for k in range(31)]
    k = 15  # t = 1.5 s: map→odom halfway between samples 1 and 2
    mo = (2.5, 0.5, 0.15)
    ob = (0.1 * k, 0.0, 0.05 * k)
    ex = mo[0] + math.cos(mo[2]) * ob[0] - math.sin(mo[2]) * ob[1]
    ey = mo[1] + math.sin(mo[2]) * ob[0] + math.cos(mo[2]) * ob[1]
    assert (pb.x[k], pb.y[k], pb.yaw[k]) == pytest.approx((ex, ey, mo[2] + ob[2]), abs=1e-12)


def test_static_mount_through_static_links_only() -> None:
    dyn = _cols([(0, "odom", "base_link", 0, 0, 0), (1, "odom", "base_link", 1, 0, 0)])
    mounts = _cols(
        [
            (0, "base_link", "ring", 0.1, 0.0, math.pi / 2),
            (0, "ring", "sonar_1", 0.2, 0.0, 0.0),
            (0, "odom", "beacon", 1.0, 1.0, 0.0),
        ]
    )
    links = tflib.build_links([(dyn, False), (mounts, True)])
    m = tflib.static_mount(links, "base_link", "sonar_1")
    assert m is not None
    assert (m.x, m.y, m.yaw) == pytest.approx((0.1, 0.2, math.pi / 2))
    assert tflib.static_mount(links, "base_link", "beacon") is None  # behind a moving link
    assert tflib.static_mount(links, "base_link", "unknown") is None
    assert tflib.static_mount(links, "base_link", "base_link") == tflib.SensorMount(0.0, 0.0, 0.0)
    # Mount of the base frame seen from a child: the inverse.
    inv = tflib.static_mount(links, "sonar_1", "base_link")
    assert inv is not None
    assert (inv.x, inv.y, inv.yaw) == pytest.approx((-0.2, 0.1, -math.pi / 2))


def test_pose_batch_without_base_frame() -> None:
    links = tflib.build_links([(_cols([(0, "odom", "base_footprint", 0, 0, 0)]), False)])
    with pytest.raises(KeyError):
        tflib.pose_batch(links, "base_link")
