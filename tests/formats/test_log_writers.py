"""Log writers: every format read back with the independent library, bytes, refusals."""

from __future__ import annotations

import csv
import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from formats.contract import PoseBatch, SensorMount, make_range_batch
from formats.errors import ConfigError, OutputError
from formats.log_writers import (
    FORMATS,
    LogContent,
    serialize_ranges,
    typestore,
    write_log,
)
from pipeline.tools.simulate import SimOptions, simulate
from pipeline.tools.simulate.world import World

T0 = 1_700_000_000_123_456_789


def _content() -> LogContent:
    """Seven readings of three sensors (names of different lengths, REP 117 values)."""
    t = T0 + np.array([0, 10, 20, 30, 40, 50, 60], np.int64) * 1_000_000
    ranges = make_range_batch(
        t,
        [0, 1, 2, 0, 1, 2, 0],
        [1.25, math.inf, 0.3, -math.inf, math.nan, 4.0, 2.0000001],
        math.radians(30),
        [0.1, 0.1, 0.2, 0.1, 0.1, 0.2, 0.1],
        5.0,
        scan_id=[0, 0, 0, 1, 1, 1, 2],
    )
    poses = PoseBatch(
        T0 + np.array([-5, 25, 55], np.int64) * 1_000_000,
        np.array([0.0, 0.1, 0.2]),
        np.array([0.0, 0.0, 0.05]),
        np.array([3.1, -3.1, -3.0]),
        "odom",
        "base_link",
    )
    mounts = {
        "front": SensorMount(0.2, 0.0, 0.0),
        "left_sonar": SensorMount(0.0, 0.15, math.pi / 2),
        "r": SensorMount(-0.2, 0.0, math.pi),
    }
    return LogContent(ranges, ("front", "left_sonar", "r"), poses, mounts)


def test_vectorised_range_serialization_matches_rosbags() -> None:
    c = _content()
    for encoding in ("cdr", "ros1"):
        ts = typestore(encoding)
        T = ts.types
        buf, off, length = serialize_ranges(c, encoding)
        for i in range(len(c.ranges)):
            sec, nsec = divmod(int(c.ranges.t_ns[i]), 10**9)
            hdr: dict[str, Any] = {
                "stamp": T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                "frame_id": c.sensor_names[c.ranges.sensor_id[i]],
            }
            if encoding == "ros1":
                hdr["seq"] = i
            msg = T["sensor_msgs/msg/Range"](
                header=T["std_msgs/msg/Header"](**hdr),
                radiation_type=0,
                field_of_view=float(c.ranges.fov_rad[i]),
                min_range=float(c.ranges.min_range_m[i]),
                max_range=float(c.ranges.max_range_m[i]),
                range=float(c.ranges.range_m[i]),
            )
            ser = ts.serialize_cdr if encoding == "cdr" else ts.serialize_ros1
            expect = bytes(ser(msg, "sensor_msgs/msg/Range"))
            got = buf[off[i] : off[i] + length[i]].tobytes()
            assert got == expect, (encoding, i)


def _check_ros_messages(msgs: dict[str, list[tuple[int, Any]]], c: LogContent) -> None:
    assert [len(msgs[t]) for t in ("/sonar", "/odom", "/tf_static")] == [7, 3, 1]
    sonar = msgs["/sonar"]
    for i, (stamp, m) in enumerate(sonar):
        assert stamp == c.ranges.t_ns[i]
        assert m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == c.ranges.t_ns[i]
        assert m.header.frame_id == c.sensor_names[c.ranges.sensor_id[i]]
        assert m.radiation_type == 0
        expect = np.float32(c.ranges.range_m[i])
        assert (math.isnan(m.range) and np.isnan(expect)) or np.float32(m.range) == expect
        assert np.float32(m.field_of_view) == np.float32(math.radians(30))
        assert np.float32(m.min_range) == np.float32(c.ranges.min_range_m[i])
        assert m.max_range == 5.0
    # Odometry: in time order, among the ranges; exact float64 poses.
    odom = msgs["/odom"]
    assert [s for s, _ in odom] == c.poses.t_ns.tolist()
    for i, (_, m) in enumerate(odom):
        assert m.header.frame_id == "odom" and m.child_frame_id == "base_link"
        assert m.pose.pose.position.x == c.poses.x[i]
        assert m.pose.pose.position.y == c.poses.y[i]
        q = m.pose.pose.orientation
        assert 2 * math.atan2(q.z, q.w) == pytest.approx(c.poses.yaw[i], abs=1e-12)
    stamp, tf = msgs["/tf_static"][0]
    assert stamp == c.poses.t_ns[0]  # the first stamp of the log
    frames = {t.child_frame_id: t for t in tf.transforms}
    assert sorted(frames) == ["front", "left_sonar", "r"]
    left = frames["left_sonar"]
    assert left.header.frame_id == "base_link"
    assert left.transform.translation.y == 0.15
    assert 2 * math.atan2(left.transform.rotation.z, left.transform.rotation.w) == pytest.approx(
        math.pi / 2
    )


def _read_any(path: Path) -> tuple[dict[str, list[tuple[int, Any]]], list[int]]:
    from rosbags.highlevel import AnyReader

    msgs: dict[str, list[tuple[int, Any]]] = {}
    order = []
    with AnyReader([path], default_typestore=typestore("cdr")) as reader:
        for conn, stamp, raw in reader.messages():
            msgs.setdefault(conn.topic, []).append((stamp, reader.deserialize(raw, conn.msgtype)))
            order.append(stamp)
    return msgs, order


@pytest.mark.parametrize(
    ("fmt", "name", "compression"),
    [
        ("ros1", "log.bag", "none"),
        ("ros1", "log.bag", "bz2"),
        ("ros1", "log.bag", "lz4"),
        ("ros2", "bag2", "none"),
        ("ros2-mcap", "bag2m", "none"),
    ],
)
def test_rosbags_reads_back_bags(tmp_path: Path, fmt: str, name: str, compression: str) -> None:
    c = _content()
    out = write_log(c, tmp_path / name, fmt, compression=compression)
    msgs, order = _read_any(out)
    _check_ros_messages(msgs, c)
    assert order == sorted(order)


def test_ros2_bag_storage_and_tf_static_qos(tmp_path: Path) -> None:
    import yaml

    write_log(_content(), tmp_path / "b", "ros2")
    meta = yaml.safe_load((tmp_path / "b" / "metadata.yaml").read_text())
    info = meta["rosbag2_bagfile_information"]
    assert info["storage_identifier"] == "sqlite3" and info["message_count"] == 11
    topics = {
        t["topic_metadata"]["name"]: t["topic_metadata"] for t in info["topics_with_message_count"]
    }
    assert topics["/sonar"]["type"] == "sensor_msgs/msg/Range"
    qos = topics["/tf_static"]["offered_qos_profiles"]
    assert "durability: 1" in str(qos) or "transient_local" in str(qos)


@pytest.mark.parametrize(
    ("fmt", "compression"), [("mcap", "none"), ("mcap", "zstd"), ("mcap-ros1", "lz4")]
)
def test_mcap_library_reads_back_standalone_mcap(
    tmp_path: Path, fmt: str, compression: str
) -> None:
    from mcap.reader import make_reader

    c = _content()
    out = write_log(c, tmp_path / "log.mcap", fmt, compression=compression)
    ros1 = fmt == "mcap-ros1"
    ts = typestore("ros1" if ros1 else "cdr")
    msgs: dict[str, list[tuple[int, Any]]] = {}
    with out.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        header = reader.get_header()
        assert header.profile == ("ros1" if ros1 else "ros2")
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == 11
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            assert schema is not None
            assert channel.message_encoding == ("ros1" if ros1 else "cdr")
            assert schema.encoding == ("ros1msg" if ros1 else "ros2msg")
            msgtype = schema.name if not ros1 else schema.name.replace("/", "/msg/", 1)
            des = ts.deserialize_ros1 if ros1 else ts.deserialize_cdr
            assert message.log_time == message.publish_time
            msgs.setdefault(channel.topic, []).append(
                (message.log_time, des(message.data, msgtype))
            )
    _check_ros_messages(msgs, c)
    if ros1:
        assert summary.channels[1].metadata["latching"] == "1"
        assert summary.schemas[1].name == "tf2_msgs/TFMessage"


def test_csv_single_layout(tmp_path: Path) -> None:
    c = _content()
    out = write_log(c, tmp_path / "log.csv", "csv")
    with out.open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == [
        "t",
        "x",
        "y",
        "yaw",
        "sensor",
        "range",
        "fov",
        "min_range",
        "max_range",
        "scan",
    ]
    assert len(rows) == 7
    assert rows[0]["t"] == "1700000000.123456789"
    assert [r["sensor"] for r in rows] == [
        "front",
        "left_sonar",
        "r",
        "front",
        "left_sonar",
        "r",
        "front",
    ]
    assert [r["range"] for r in rows[:5]] == ["1.25", "inf", "0.3", "-inf", "nan"]
    assert float(rows[6]["range"]) == c.ranges.range_m[6]  # repr round-trips exactly
    assert [r["scan"] for r in rows] == ["0", "0", "0", "1", "1", "1", "2"]
    # Pose at the reading time: t = +10 ms lies 15/30 of the way from the pose at −5 ms
    # to the one at +25 ms; yaw interpolates across ±π (3.1 → −3.1 the short way).
    assert float(rows[1]["x"]) == pytest.approx(0.05)
    yaw = float(rows[1]["yaw"])
    assert yaw == pytest.approx(math.pi, abs=1e-9) or yaw == pytest.approx(-math.pi, abs=1e-9)
    # Before the first pose / after the last the pose is held.
    assert float(rows[6]["x"]) == 0.2


def test_csv_set_layout(tmp_path: Path) -> None:
    c = _content()
    out = write_log(c, tmp_path / "run", "csv-set")
    assert sorted(p.name for p in out.iterdir()) == ["poses.csv", "ranges.csv", "sensors.csv"]
    with (out / "ranges.csv").open(newline="") as f:
        ranges = list(csv.DictReader(f))
    # Limits are constant per sensor here, so only sensors.csv carries them.
    assert list(ranges[0]) == ["t", "sensor", "range", "scan"]
    assert len(ranges) == 7 and ranges[2]["sensor"] == "r"
    with (out / "poses.csv").open(newline="") as f:
        poses = list(csv.reader(f))
    assert poses[0] == ["t", "x", "y", "yaw"]
    assert poses[1] == ["1700000000.118456789", "0.0", "0.0", "3.1"]
    with (out / "sensors.csv").open(newline="") as f:
        sensors = {r["sensor"]: r for r in csv.DictReader(f)}
    assert sorted(sensors) == ["front", "left_sonar", "r"]
    assert float(sensors["left_sonar"]["yaw"]) == math.pi / 2
    assert float(sensors["r"]["min_range"]) == 0.2
    assert float(sensors["front"]["fov"]) == math.radians(30)


def test_csv_set_keeps_per_reading_limits_when_they_vary(tmp_path: Path) -> None:
    c = _content()
    c.ranges.max_range_m[3] = 4.0  # one reading of 'front' with another r_max
    out = write_log(c, tmp_path / "run", "csv-set")
    with (out / "ranges.csv").open(newline="") as f:
        ranges = list(csv.DictReader(f))
    assert list(ranges[0]) == ["t", "sensor", "range", "fov", "min_range", "max_range", "scan"]
    assert [r["max_range"] for r in ranges][2:4] == ["5.0", "4.0"]


@pytest.mark.parametrize("fmt", FORMATS)
def test_refuses_to_overwrite_and_is_deterministic(tmp_path: Path, fmt: str) -> None:
    c = _content()
    (tmp_path / "one").mkdir()
    (tmp_path / "two").mkdir()
    a = write_log(c, tmp_path / "one" / "log", fmt)
    before = _files(a)
    with pytest.raises(OutputError, match="log: exists already, not overwriting"):
        write_log(c, a, fmt)
    assert _files(a) == before  # untouched
    # Same content, same name: identical bytes (no wall-clock time in any format).
    b = write_log(c, tmp_path / "two" / "log", fmt)
    assert _files(b) == before


def _files(p: Path) -> dict[str, bytes]:
    if p.is_file():
        return {"": p.read_bytes()}
    return {q.name: q.read_bytes() for q in sorted(p.iterdir())}


def test_bad_format_compression_and_content(tmp_path: Path) -> None:
    c = _content()
    with pytest.raises(ConfigError, match="unknown log format 'bag'"):
        write_log(c, tmp_path / "x", "bag")
    with pytest.raises(ConfigError, match="format 'ros2' takes compression \\['none', 'zstd'\\]"):
        write_log(c, tmp_path / "x", "ros2", compression="lz4")
    with pytest.raises(OutputError, match="parent directory does not exist"):
        write_log(c, tmp_path / "no" / "x.bag", "ros1")
    bad = LogContent(c.ranges, ("a,b", "x", "y"), c.poses, c.mounts)
    with pytest.raises(ConfigError, match="sensor names cannot be written to CSV"):
        write_log(bad, tmp_path / "x.csv", "csv")
    assert not (tmp_path / "x.csv").exists()


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize(("start_s", "shown"), [(-1.5, "-1.505 … -1.440"),
                                               (2**31, "2147483647.995 … 2147483648.060")])
def test_stamps_a_ros_log_cannot_hold_are_refused(tmp_path: Path, fmt: str, start_s: float,
                                                  shown: str) -> None:
    c = _content()
    ns = int(start_s * 1e9) - T0  # the first reading at start_s, the first pose 5 ms before
    poses = PoseBatch(c.poses.t_ns + ns, c.poses.x, c.poses.y, c.poses.yaw,
                      c.poses.parent_frame, c.poses.child_frame)
    ranges = dataclasses.replace(c.ranges, t_ns=c.ranges.t_ns + ns)
    moved = LogContent(ranges, c.sensor_names, poses, c.mounts)
    out = tmp_path / "log"
    if fmt.startswith("csv"):  # CSV holds any stamp
        write_log(moved, out, fmt)
        return
    with pytest.raises(OutputError, match=rf"log: stamps {shown} s cannot be written as {fmt}: "
                                          r"its stamps hold 0 … 2147483647 s"):
        write_log(moved, out, fmt)
    assert not out.exists()


def test_simulated_log_to_content_round_trip(tmp_path: Path) -> None:
    world = World(
        np.array([[-1, -1, 3, -1], [3, -1, 3, 2], [3, 2, -1, 2], [-1, 2, -1, -1]], dtype=float),
        np.empty((0, 3)),
    )
    sim = simulate(world, np.array([[0.0, 0.0], [1.0, 0.5]]), SimOptions(sonar_model="ideal", seed=4))
    c = sim.to_content()
    assert len(c.ranges) == len(sim.ranges) and len(c.poses) == len(sim.poses)
    assert sorted(c.mounts) == sorted(sim.sensor_names)
    out = write_log(c, tmp_path / "sim.bag", "ros1")
    msgs, _ = _read_any(out)
    assert len(msgs["/sonar"]) == len(sim.ranges)
    got = np.array([m.range for _, m in msgs["/sonar"]])
    np.testing.assert_array_equal(got, sim.ranges.range_m)
    names = [m.header.frame_id for _, m in msgs["/sonar"]]
    assert names == [sim.sensor_names[s] for s in sim.ranges.sensor]
    assert [s for s, _ in msgs["/odom"]] == sim.poses.t_ns.tolist()
