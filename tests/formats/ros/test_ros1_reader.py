"""RosLogReader over ROS 1 bags: ranges, poses, tf chains, mounts, rings, topic choice."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from ros1_bags import (
    DATA,
    NS,
    Msg,
    Tf,
    odom_msg,
    pointcloud_msg,
    range_msg,
    sonararray_msg,
    tf_msg,
    write_bag,
)
from rosbags.highlevel import AnyReader

from formats.contract import LogReader, MountBatch, PoseBatch, RangeBatch
from formats.errors import ConfigError, TopicError
from formats.options import InputConfig, MountConfig, SensorsConfig
from formats.presets import PRESETS
from formats.ros.reader import RosLogReader
from formats.ros.ros1bag import Ros1BagSource, open_ros1_bag
from pipeline.config import Config

MS = 1_000_000
SONARS = ["sonar_front", "sonar_left", "sonar_right", "sonar_back"]
T0 = 1_700_000_000 * NS


def _range_value(i: int) -> float:
    return round(0.3 + 0.01 * i, 2)


def _robot_messages() -> list[Msg]:
    """3 s of a robot: 4 Range sonars at 10 Hz (round robin), Odometry at 20 Hz, tf
    map→odom (1 Hz) and odom→base_link (20 Hz), static mounts on /tf_static, one mount
    repeated unchanged on /tf. Header stamps lag log times by 2 ms."""
    msgs: list[Msg] = [
        Msg(
            "/tf_static",
            "tf2_msgs/msg/TFMessage",
            T0,
            tf_msg(
                [
                    Tf(T0, "base_link", "sonar_front", 0.2, 0.0, 0.0),
                    Tf(T0, "base_link", "sonar_mount_left", 0.0, 0.1, 0.0),
                    Tf(T0, "sonar_mount_left", "sonar_left", 0.05, 0.0, math.pi / 2),
                    Tf(T0, "base_link", "sonar_right", 0.0, -0.1, -math.pi / 2),
                ]
            ),
        )
    ]
    for i in range(120):  # 4 sonars × 10 Hz × 3 s
        t = T0 + 25 * MS * i + MS
        msgs.append(
            Msg(
                "/sonar",
                "sensor_msgs/msg/Range",
                t,
                range_msg(t - 2 * MS, SONARS[i % 4], _range_value(i)),
            )
        )
    for k in range(60):
        t = T0 + 50 * MS * k
        msgs.append(
            Msg(
                "/odom",
                "nav_msgs/msg/Odometry",
                t + 3 * MS,
                odom_msg(t, 0.02 * k, 0.01 * k, 0.03 * k),
            )
        )
        tfs = [Tf(t, "odom", "base_link", 0.02 * k, 0.01 * k, 0.03 * k)]
        if k % 20 == 0:
            tfs.append(Tf(t, "map", "odom", 1.0 + 0.1 * (k // 20), -0.5, 0.2 * (k // 20)))
        tfs.append(Tf(t, "base_link", "sonar_back", -0.2, 0.0, math.pi))
        msgs.append(Msg("/tf", "tf2_msgs/msg/TFMessage", t + 4 * MS, tf_msg(tfs)))
    return sorted(msgs, key=lambda m: m.t_ns)


def _robot_bag(path: Path, compression: str = "none", *, unsorted: bool = False) -> Path:
    msgs = _robot_messages()
    if unsorted:  # second half first: chunks are written out of time order
        msgs = msgs[len(msgs) // 2 :] + msgs[: len(msgs) // 2]
    return write_bag(path, msgs, compression=compression, chunk_threshold=3000)


def _collect(
    reader: RosLogReader, kinds: tuple[str, ...] = ("ranges", "poses", "mounts")
) -> list[object]:
    return list(reader.batches(kinds))  # type: ignore[arg-type]


def _ranges(batches: list[object]) -> RangeBatch:
    return RangeBatch.concat([b for b in batches if isinstance(b, RangeBatch)])


@pytest.mark.parametrize(
    ("compression", "unsorted"),
    [("none", False), ("bz2", False), ("lz4", False), ("lz4", True), ("none", True)],
)
def test_robot_bag_ranges_poses_mounts(tmp_path: Path, compression: str, unsorted: bool) -> None:
    path = _robot_bag(tmp_path / "robot.bag", compression, unsorted=unsorted)
    with open_ros1_bag(path) as reader:
        assert isinstance(reader, LogReader)
        with Ros1BagSource(path) as src:
            assert src.chunk_count > 5
        batches = _collect(reader)
        names = list(reader.sensor_names)
    # The mounts come once, last: their Range frames are learnt from the readings' stream.
    mounts = batches[-1]
    assert isinstance(mounts, MountBatch)
    assert sum(isinstance(b, MountBatch) for b in batches) == 1
    # Asked alone, the same mounts (from a pass over the Range frames and tf).
    with open_ros1_bag(path) as alone:
        only = _collect(alone, ("mounts",))
    assert len(only) == 1 and only[0] == mounts
    assert mounts.base_frame == "base_link"
    assert sorted(mounts.mounts) == sorted(SONARS)
    left = mounts.mounts["sonar_left"]
    assert (left.x, left.y, left.yaw) == pytest.approx((0.05, 0.1, math.pi / 2))
    back = mounts.mounts["sonar_back"]  # from /tf, never changing
    assert (back.x, back.y, abs(back.yaw)) == pytest.approx((-0.2, 0.0, math.pi))
    front = mounts.mounts["sonar_front"]
    assert (front.x, front.y, front.yaw) == pytest.approx((0.2, 0.0, 0.0))

    r = _ranges(batches)
    assert len(r) == 120
    assert np.all(np.diff(r.record_t_ns) >= 0)  # log order even for unsorted chunks
    i = np.arange(120)
    assert r.record_t_ns.tolist() == (T0 + 25 * MS * i + MS).tolist()
    assert r.t_ns.tolist() == (T0 + 25 * MS * i - MS).tolist()
    assert r.range_m.tolist() == [float(np.float32(_range_value(k))) for k in range(120)]
    assert [names[s] for s in r.sensor_id] == [SONARS[k % 4] for k in range(120)]
    assert names == SONARS  # sensor ids in order of first appearance
    assert set(r.fov_rad.tolist()) == {float(np.float32(0.5))}
    assert set(r.max_range_m.tolist()) == {4.0}
    assert np.isnan(r.variance).all()
    assert (r.scan_id == -1).all()

    poses = [b for b in batches if isinstance(b, PoseBatch)]
    assert {(p.parent_frame, p.child_frame) for p in poses} == {("odom", "base_link")}
    t = np.concatenate([p.t_ns for p in poses])
    x = np.concatenate([p.x for p in poses])
    yaw = np.concatenate([p.yaw for p in poses])
    rec = np.concatenate([p.record_t_ns for p in poses if p.record_t_ns is not None])
    k = np.arange(60)
    assert t.tolist() == (T0 + 50 * MS * k).tolist()
    assert rec.tolist() == (t + 3 * MS).tolist()
    np.testing.assert_allclose(x, 0.02 * k)
    np.testing.assert_allclose(yaw, 0.03 * k, atol=1e-12)


def test_same_output_for_every_compression_and_repeated_passes(tmp_path: Path) -> None:
    results = []
    for comp in ("none", "bz2", "lz4"):
        with open_ros1_bag(_robot_bag(tmp_path / f"{comp}.bag", comp)) as reader:
            first = _ranges(_collect(reader, ("ranges",)))
            again = _ranges(_collect(reader, ("ranges",)))
        assert all(
            np.array_equal(getattr(first, f), getattr(again, f), equal_nan=True)
            for f in ("t_ns", "sensor_id", "range_m")
        )
        results.append(first)
    for other in results[1:]:
        assert np.array_equal(results[0].range_m, other.range_m)
        assert np.array_equal(results[0].t_ns, other.t_ns)


def test_tf_chain_as_pose_source(tmp_path: Path) -> None:
    path = _robot_bag(tmp_path / "robot.bag", "lz4")
    cfg = Config(input=InputConfig(pose_topic="/tf"))
    with open_ros1_bag(path, cfg) as reader:
        batches = _collect(reader, ("poses",))
        info = reader.info()
    (pb,) = batches
    assert isinstance(pb, PoseBatch)
    assert (pb.parent_frame, pb.child_frame) == ("map", "base_link")
    # odom→base_link (20 Hz) is the fastest link; map→odom spans 0..2 s (k = 0..40).
    k = np.arange(41)
    assert pb.t_ns.tolist() == (T0 + 50 * MS * k).tolist()
    j = 30  # t = 1.5 s: map→odom halfway between its samples at 1 s and 2 s
    mo = (1.15, -0.5, 0.3)
    ob = (0.02 * j, 0.01 * j, 0.03 * j)
    ex = mo[0] + math.cos(mo[2]) * ob[0] - math.sin(mo[2]) * ob[1]
    ey = mo[1] + math.sin(mo[2]) * ob[0] + math.cos(mo[2]) * ob[1]
    assert (pb.x[j], pb.y[j], pb.yaw[j]) == pytest.approx((ex, ey, mo[2] + ob[2]), abs=1e-9)
    assert info.pose_topic == "/tf"
    assert "poses from the tf chain to base_link (/tf)" in info.notes


def test_tf_discovered_when_there_is_no_odometry(tmp_path: Path) -> None:
    msgs = [m for m in _robot_messages() if m.topic != "/odom"]
    with open_ros1_bag(write_bag(tmp_path / "tf.bag", msgs)) as reader:
        assert reader.pose_topic == "/tf"
        (pb,) = _collect(reader, ("poses",))
    assert isinstance(pb, PoseBatch) and pb.parent_frame == "map" and len(pb) == 41


def test_info_of_robot_bag(tmp_path: Path) -> None:
    with open_ros1_bag(_robot_bag(tmp_path / "robot.bag")) as reader:
        info = reader.info()
    assert info.format == "ros1"
    assert [(t.name, t.msgtype, t.count, t.encoding, t.role) for t in info.topics] == [
        ("/tf_static", "tf2_msgs/msg/TFMessage", 1, "ros1", "tf_static"),
        ("/sonar", "sensor_msgs/msg/Range", 120, "ros1", "range"),
        ("/odom", "nav_msgs/msg/Odometry", 60, "ros1", "pose"),
        ("/tf", "tf2_msgs/msg/TFMessage", 60, "ros1", "tf"),
    ]
    assert info.message_count == 241
    assert (info.start_ns, info.end_ns) == (T0, T0 + 25 * MS * 119 + MS)  # last Range
    assert info.range_topics == ["/sonar"]
    assert info.pose_topic == "/odom"
    assert info.notes == [
        "/sonar: 4 range sensors: sonar_front fov 0.50 rad 0.02-4.00 m, sonar_left fov 0.50 rad "
        "0.02-4.00 m, sonar_right fov 0.50 rad 0.02-4.00 m, sonar_back fov 0.50 rad 0.02-4.00 m"
    ]


def test_tiago_sonar_through_reader() -> None:
    with open_ros1_bag(
        DATA / "tiago-sonar.bag", Config(input=InputConfig(pose_topic=""))
    ) as reader:
        info = reader.info()
        r = _ranges(_collect(reader, ("ranges", "mounts")))
        names = list(reader.sensor_names)
    assert info.topics[0].count == 609
    assert info.notes[-1] == (
        "/sonar_base: 3 range sensors: base_sonar_01_link fov 0.50 rad 0.02-1.00 m, "
        "base_sonar_02_link fov 0.50 rad 0.02-1.00 m, base_sonar_03_link fov 0.50 rad 0.02-1.00 m"
    )
    assert info.notes[0].startswith("no pose source")
    with AnyReader([DATA / "tiago-sonar.bag"]) as ref:
        items: list[tuple[int, Any]] = [
            (t, ref.deserialize(d, c.msgtype)) for c, t, d in ref.messages()
        ]
    assert len(r) == 609
    assert r.record_t_ns.tolist() == [t for t, _m in items]
    assert r.range_m.tolist() == [m.range for _t, m in items]
    assert [names[s] for s in r.sensor_id] == [m.header.frame_id for _t, m in items]


# ------------------------------------------------------------------ sonar rings


def test_pointcloud_ring_with_preset(tmp_path: Path) -> None:
    ring = PRESETS["pioneer-p3dx"]
    dist = [[0.5 + 0.1 * s + m for s in range(16)] for m in range(3)]
    msgs = []
    for m in range(3):
        pts = []
        for s, mc in enumerate(ring):
            a = math.radians(mc.yaw_deg)
            pts.append((mc.x + dist[m][s] * math.cos(a), mc.y + dist[m][s] * math.sin(a)))
        msgs.append(
            Msg(
                "/sonar",
                "sensor_msgs/msg/PointCloud",
                T0 + m * 100 * MS,
                pointcloud_msg(T0 + m * 100 * MS - MS, pts),
            )
        )
    msgs.append(Msg("/odom", "nav_msgs/msg/Odometry", T0, odom_msg(T0, 0, 0, 0)))
    path = write_bag(tmp_path / "pc.bag", msgs, chunk_threshold=600)
    cfg = Config(sensors=SensorsConfig(preset="pioneer-p3dx"))
    with open_ros1_bag(path, cfg) as reader:
        r = _ranges(_collect(reader, ("ranges",)))
        names = list(reader.sensor_names)
        info = reader.info()
    assert len(r) == 48
    np.testing.assert_allclose(r.range_m, np.ravel(dist), atol=2e-6)  # points are float32
    assert [names[s] for s in r.sensor_id] == [f"sonar_{s}" for s in range(16)] * 3
    assert r.scan_id.tolist() == [0] * 16 + [1] * 16 + [2] * 16
    assert r.t_ns.tolist() == [T0 + m * 100 * MS - MS for m in range(3) for _ in range(16)]
    np.testing.assert_allclose(r.fov_rad, math.radians(30.0))
    assert set(r.min_range_m.tolist()) == {0.1} and set(r.max_range_m.tolist()) == {5.0}
    assert "/sonar: PointCloud sonar ring, 16 mounts from preset 'pioneer-p3dx'" in info.notes


def test_pointcloud_without_mounts_is_a_config_error(tmp_path: Path) -> None:
    msgs = [Msg("/sonar", "sensor_msgs/msg/PointCloud", T0, pointcloud_msg(T0, [(1.0, 0.0)]))]
    with open_ros1_bag(write_bag(tmp_path / "pc.bag", msgs)) as reader:
        with pytest.raises(
            ConfigError,
            match=r"pc\.bag: topic /sonar is sensor_msgs/msg/PointCloud, .*sensors\.preset",
        ):
            _collect(reader, ("ranges",))
        assert any("sensors.preset" in n for n in reader.info().notes)


def test_pointcloud_with_more_points_than_mounts(tmp_path: Path) -> None:
    msgs = [Msg("/sonar", "sensor_msgs/msg/PointCloud", T0, pointcloud_msg(T0, [(1.0, 0.0)] * 9))]
    cfg = Config(sensors=SensorsConfig(preset="udacity-8sonar"))
    with (
        open_ros1_bag(write_bag(tmp_path / "pc.bag", msgs), cfg) as reader,
        pytest.raises(
            ConfigError, match="has 9 points per message but preset 'udacity-8sonar' has 8 mounts"
        ),
    ):
        _collect(reader, ("ranges",))


def test_sonararray_drops_republished_values(tmp_path: Path) -> None:
    values = [
        [1.0, 2.0, 3.0, 4.0],
        [1.0, 2.5, 3.0, 4.5],  # sonars 0 and 2 did not refresh
        [1.0, 2.5, 3.5, 4.6],  # sonars 0 and 1 did not refresh
        [1.1, 2.5, 3.5, 4.6],  # only sonar 0 refreshed
    ]
    msgs = [
        Msg(
            "/sonar",
            "p2os_msgs/msg/SonarArray",
            T0 + m * 100 * MS,
            sonararray_msg(T0 + m * 100 * MS, v),
        )
        for m, v in enumerate(values)
    ]
    mounts = tuple(MountConfig(name=f"s{i}", x=0.1 * i, fov_deg=20.0 + i) for i in range(4))
    cfg = Config(sensors=SensorsConfig(mounts=mounts, min_range=0.05, max_range=3.0))
    # Small chunks: the previous values must carry over from chunk to chunk.
    path = write_bag(tmp_path / "p2os.bag", msgs, chunk_threshold=100)
    with open_ros1_bag(path, cfg) as reader:
        with Ros1BagSource(path) as src:
            assert src.chunk_count == 4
        first = _ranges(_collect(reader, ("ranges",)))
        second = _ranges(_collect(reader, ("ranges",)))
        names = list(reader.sensor_names)
    for r in (first, second):
        assert r.range_m.tolist() == [1.0, 2.0, 3.0, 4.0, 2.5, 4.5, 3.5, 4.6, 1.1]
        assert [names[s] for s in r.sensor_id] == [
            "s0",
            "s1",
            "s2",
            "s3",
            "s1",
            "s3",
            "s2",
            "s3",
            "s0",
        ]
        assert r.scan_id.tolist() == [0, 0, 0, 0, 1, 1, 2, 2, 3]
        np.testing.assert_allclose(r.fov_rad, np.radians([20, 21, 22, 23, 21, 23, 22, 23, 20]))
        assert set(r.min_range_m.tolist()) == {0.05} and set(r.max_range_m.tolist()) == {3.0}


# ------------------------------------------------------------------ topic selection


def _bag_with(tmp_path: Path, topics: dict[str, str]) -> Path:
    msgs = []
    for topic, kind in topics.items():
        if kind == "odom":
            msgs.append(Msg(topic, "nav_msgs/msg/Odometry", T0, odom_msg(T0, 0, 0, 0)))
        else:
            msgs.append(Msg(topic, "sensor_msgs/msg/Range", T0, range_msg(T0, "s", 1.0)))
    return write_bag(tmp_path / "t.bag", msgs)


def test_two_odometry_topics_are_ambiguous(tmp_path: Path) -> None:
    path = _bag_with(tmp_path, {"/sonar": "range", "/odom": "odom", "/odom_filtered": "odom"})
    with open_ros1_bag(path) as reader:
        with pytest.raises(
            TopicError,
            match=r"t\.bag: several odometry topics \(/odom, /odom_filtered\): choose one with "
            r"input\.pose_topic; the log contains: /sonar:sensor_msgs/msg/Range, "
            r"/odom:nav_msgs/msg/Odometry, /odom_filtered:nav_msgs/msg/Odometry$",
        ):
            _collect(reader, ("poses",))
        # Ranges alone are still readable.
        assert len(_ranges(_collect(reader, ("ranges",)))) == 1
    cfg = Config(input=InputConfig(pose_topic="/odom_filtered"))
    with open_ros1_bag(path, cfg) as reader:
        (pb,) = _collect(reader, ("poses",))
        assert isinstance(pb, PoseBatch) and len(pb) == 1


def test_requested_topics_missing_or_of_wrong_type(tmp_path: Path) -> None:
    path = _bag_with(tmp_path, {"/sonar": "range", "/odom": "odom"})
    contains = "the log contains: /sonar:sensor_msgs/msg/Range, /odom:nav_msgs/msg/Odometry"
    cases = [
        (
            InputConfig(range_topics=("/sonar", "/nope")),
            "ranges",
            "range topic /nope is not in the log; ",
        ),
        (
            InputConfig(range_topics=("/odom",)),
            "ranges",
            "range topic /odom is nav_msgs/msg/Odometry, not ",
        ),
        (InputConfig(pose_topic="/pose"), "poses", "pose topic /pose is not in the log; "),
        (
            InputConfig(pose_topic="/sonar"),
            "poses",
            "pose topic /sonar is sensor_msgs/msg/Range, not ",
        ),
    ]
    for inp, kind, message in cases:
        with open_ros1_bag(path, Config(input=inp)) as reader, pytest.raises(TopicError) as err:
            _collect(reader, (kind,))
        assert err.value.reason.startswith(message)
        assert err.value.reason.endswith(contains)


def test_no_range_topic(tmp_path: Path) -> None:
    path = _bag_with(tmp_path, {"/odom": "odom"})
    with (
        open_ros1_bag(path) as reader,
        pytest.raises(
            TopicError, match=r"no range topic .*; the log contains: /odom:nav_msgs/msg/Odometry$"
        ),
    ):
        _collect(reader, ("ranges",))


def test_tf_without_the_base_frame(tmp_path: Path) -> None:
    path = _robot_bag(tmp_path / "robot.bag")
    cfg = Config(input=InputConfig(pose_topic="/tf", base_frame="base_footprint"))
    with (
        open_ros1_bag(path, cfg) as reader,
        pytest.raises(
            TopicError,
            match=r"tf has no transform to the base frame 'base_footprint' .*frames in tf: base_link, map,",
        ),
    ):
        _collect(reader, ("poses",))


# ------------------------------------------------------------------ damaged logs


def test_truncated_bag_yields_intact_part_with_a_note(tmp_path: Path) -> None:
    path = _robot_bag(tmp_path / "robot.bag", "lz4")
    data = path.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: len(data) // 2])
    with open_ros1_bag(cut) as reader:
        info = reader.info()
        r = _ranges(_collect(reader))
    assert 0 < len(r) < 120
    assert r.range_m.tolist() == [float(np.float32(_range_value(k))) for k in range(len(r))]
    assert info.notes[0].startswith(f"{cut}: index position ")
    assert "bytes at the end lost" in info.notes[0]


def test_a_message_that_does_not_decode_is_lost_and_named(tmp_path: Path) -> None:
    """Issue 58 item 9: one bad message loses itself, not the log; the loss names the
    file, the topic and the message."""
    from rosbags.rosbag1 import Writer

    path = tmp_path / "bad.bag"
    from ros1_bags import range_msg, store

    with Writer(path) as w:
        conn = w.add_connection("/sonar", "sensor_msgs/msg/Range", typestore=store())
        for k in range(5):
            msg = range_msg(T0 + k * 10**8, "s0", 1.0 + k)
            w.write(conn, T0 + k * 10**8, store().serialize_ros1(msg, "sensor_msgs/msg/Range"))
        w.write(conn, T0 + 5 * 10**8, bytes(range(20)))  # the sixth: garbage
        w.write(conn, T0 + 6 * 10**8, store().serialize_ros1(
            range_msg(T0 + 6 * 10**8, "s0", 7.0), "sensor_msgs/msg/Range"))
    with open_ros1_bag(path) as reader:
        ranges = _ranges(_collect(reader, ("ranges",)))
        (loss,) = reader.info().losses
    assert ranges.range_m.tolist() == [1.0, 2.0, 3.0, 4.0, 5.0, 7.0]
    t_bad = T0 + 5 * 10**8
    assert loss.startswith(f"bad.bag: /sonar: 1 messages do not decode and are lost (first:"
                           f" message 5 of topic /sonar (log time {t_bad} ns)")


def test_reader_works_on_any_source_object(tmp_path: Path) -> None:
    # Only the MessageSource interface is used: a plain RosLogReader over the source.
    src = Ros1BagSource(_robot_bag(tmp_path / "robot.bag"))
    with RosLogReader(src, Config()) as reader:
        assert reader.format_name == "ros1"
        assert reader.path == src.path
        assert reader.range_topics == ["/sonar"]
