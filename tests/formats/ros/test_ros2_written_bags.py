"""Bags written here with rosbags' Writer and the mcap library: exact decoded values."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.typesys import Stores, get_typestore

from formats.ros.columns import PoseColumns, RangeColumns, TransformColumns
from formats.ros.decode import decode
from formats.ros.decode_cdr import decode_cdr
from formats.ros.mcap_source import McapSource
from formats.ros.ros2bag import Ros2BagSource

JAZZY = get_typestore(Stores.ROS2_JAZZY)  # Range has `variance`
HUMBLE = get_typestore(Stores.ROS2_HUMBLE)  # Range without it
FRAMES = ["sonar_front", "sonar_left", "s2"]
N = 30


def _header(ts: Any, i: int, frame: str) -> Any:
    t = ts.types["builtin_interfaces/msg/Time"](sec=1000 + i, nanosec=7 * i)
    return ts.types["std_msgs/msg/Header"](stamp=t, frame_id=frame)


def _range(ts: Any, i: int) -> Any:
    kw: dict[str, Any] = dict(
        header=_header(ts, i, FRAMES[i % 3]),
        radiation_type=0,
        field_of_view=0.5,
        min_range=0.02,
        max_range=5.0,
        range=0.125 * i,
    )
    if ts is JAZZY:
        kw["variance"] = 0.25
    return ts.types["sensor_msgs/msg/Range"](**kw)


def _odom(ts: Any, i: int) -> Any:
    g = ts.types
    pose = g["geometry_msgs/msg/Pose"](
        position=g["geometry_msgs/msg/Point"](x=0.5 * i, y=-1.0, z=0.0),
        orientation=g["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.6, w=0.8),
    )
    twist = g["geometry_msgs/msg/Twist"](
        linear=g["geometry_msgs/msg/Vector3"](x=1.0, y=0.0, z=0.0),
        angular=g["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.1),
    )
    return g["nav_msgs/msg/Odometry"](
        header=_header(ts, i, "odom"),
        child_frame_id="base_link",
        pose=g["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
        twist=g["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
    )


def _tf(ts: Any, i: int, child: str) -> Any:
    g = ts.types
    tr = g["geometry_msgs/msg/Transform"](
        translation=g["geometry_msgs/msg/Vector3"](x=0.2, y=0.1 * i, z=0.0),
        rotation=g["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
    )
    st = g["geometry_msgs/msg/TransformStamped"](
        header=_header(ts, i, "base_link"), child_frame_id=child, transform=tr
    )
    return g["tf2_msgs/msg/TFMessage"](transforms=[st])


def write_bag(path: Path, ts: Any, storage: StoragePlugin, mode: CompressionMode) -> Path:
    w = Writer(path, version=9, storage_plugin=storage)
    if mode != CompressionMode.NONE:
        w.set_compression(mode, CompressionFormat.ZSTD)
    with w:
        rng = w.add_connection("/sonar", "sensor_msgs/msg/Range", typestore=ts)
        odo = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts)
        tf = w.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ts)
        tfs = w.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=ts)
        w.write(tfs, 0, ts.serialize_cdr(_tf(ts, 0, "sonar_front"), "tf2_msgs/msg/TFMessage"))
        for i in range(N):
            t = 10_000 + 100 * i
            w.write(rng, t, ts.serialize_cdr(_range(ts, i), "sensor_msgs/msg/Range"))
            if i % 3 == 0:
                w.write(odo, t + 1, ts.serialize_cdr(_odom(ts, i), "nav_msgs/msg/Odometry"))
                w.write(tf, t + 2, ts.serialize_cdr(_tf(ts, i, "odom"), "tf2_msgs/msg/TFMessage"))
    return path


def _decoded(src: Any, topic: str) -> list[Any]:
    return [decode(b) for b in src.raw_batches([c.id for c in src.connections if c.topic == topic])]


def _ranges(src: Any) -> RangeColumns:
    cols = _decoded(src, "/sonar")
    assert all(isinstance(c, RangeColumns) for c in cols)
    return RangeColumns(
        stamp_ns=np.concatenate([c.stamp_ns for c in cols]),
        frame=np.concatenate([np.asarray(c.frames)[c.frame] for c in cols]),
        frames=[],
        radiation_type=np.concatenate([c.radiation_type for c in cols]),
        field_of_view=np.concatenate([c.field_of_view for c in cols]),
        min_range=np.concatenate([c.min_range for c in cols]),
        max_range=np.concatenate([c.max_range for c in cols]),
        range=np.concatenate([c.range for c in cols]),
        variance=np.concatenate([c.variance for c in cols]),
    )


def _check_content(src: Any, ts: Any) -> None:
    r = _ranges(src)
    i = np.arange(N)
    assert r.stamp_ns.tolist() == ((1000 + i) * 1_000_000_000 + 7 * i).tolist()
    assert r.frame.tolist() == [FRAMES[k % 3] for k in range(N)]
    np.testing.assert_array_equal(r.range, 0.125 * i)
    np.testing.assert_array_equal(r.field_of_view, np.float32(0.5))
    np.testing.assert_array_equal(r.min_range, np.float32(0.02))
    np.testing.assert_array_equal(r.max_range, 5.0)
    if ts is JAZZY:
        np.testing.assert_array_equal(r.variance, 0.25)
    else:
        assert np.isnan(r.variance).all()

    (odo,) = _decoded(src, "/odom")
    assert isinstance(odo, PoseColumns)
    assert odo.frames == ["odom", "base_link"]
    assert odo.frame.tolist() == [0] * 10 and odo.child.tolist() == [1] * 10
    np.testing.assert_array_equal(odo.x, 0.5 * np.arange(0, N, 3))
    np.testing.assert_array_equal(odo.y, -1.0)
    np.testing.assert_array_equal(odo.qz, 0.6)
    np.testing.assert_array_equal(odo.qw, 0.8)

    (tf,) = _decoded(src, "/tf")
    assert isinstance(tf, TransformColumns)
    assert tf.frames == ["base_link", "odom"]
    assert tf.msg_index.tolist() == list(range(10))
    np.testing.assert_allclose(tf.y, 0.1 * np.arange(0, N, 3))
    (tfs,) = _decoded(src, "/tf_static")
    assert isinstance(tfs, TransformColumns)
    assert [tfs.frames[c] for c in tfs.child] == ["sonar_front"]
    np.testing.assert_array_equal(tfs.x, 0.2)


# Storage (chunk) compression exists for MCAP storage only.
_CASES = [
    (storage, mode)
    for storage in (StoragePlugin.SQLITE3, StoragePlugin.MCAP)
    for mode in (CompressionMode.NONE, CompressionMode.MESSAGE, CompressionMode.FILE,
                 CompressionMode.STORAGE)
    if not (mode == CompressionMode.STORAGE and storage == StoragePlugin.SQLITE3)
]


@pytest.mark.parametrize(("storage", "mode"), _CASES)
def test_rosbags_written_bag(tmp_path: Path, storage: StoragePlugin, mode: CompressionMode) -> None:
    bag = write_bag(tmp_path / "bag", JAZZY, storage, mode)
    with Ros2BagSource(bag) as src:
        assert {c.topic: c.count for c in src.connections} == {
            "/sonar": N,
            "/odom": 10,
            "/tf": 10,
            "/tf_static": 1,
        }
        assert src.start_ns == 0 and src.end_ns == 10_000 + 100 * (N - 1)  # last Range
        sonar = next(c for c in src.connections if c.topic == "/sonar")
        assert "float32 variance" in sonar.msgdef
        _check_content(src, JAZZY)
        assert src.warnings == []


def test_range_without_variance_humble(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "bag", HUMBLE, StoragePlugin.MCAP, CompressionMode.NONE)
    with Ros2BagSource(bag) as src:
        _check_content(src, HUMBLE)


def test_range_variance_from_length_without_msgdef(tmp_path: Path) -> None:
    for ts, expect in ((JAZZY, 0.25), (HUMBLE, None)):
        bag = write_bag(tmp_path / f"bag{expect}", ts, StoragePlugin.MCAP, CompressionMode.NONE)
        with Ros2BagSource(bag) as src:
            conn = next(c for c in src.connections if c.topic == "/sonar")
            from dataclasses import replace

            (batch,) = src.raw_batches([conn.id])
            bare = type(batch)(
                replace(conn, msgdef="", msgdef_format=""),
                batch.log_time_ns,
                batch.buffer,
                batch.offsets,
                batch.lengths,
            )
            cols = decode_cdr(bare)
            assert isinstance(cols, RangeColumns)
            if expect is None:
                assert np.isnan(cols.variance).all()
            else:
                np.testing.assert_array_equal(cols.variance, expect)


def test_split_bag_written_in_two_parts(tmp_path: Path) -> None:
    # Two rosbags bags whose storage files are joined by a hand-written metadata.yaml.
    a = write_bag(tmp_path / "a", JAZZY, StoragePlugin.SQLITE3, CompressionMode.NONE)
    b = write_bag(tmp_path / "b", HUMBLE, StoragePlugin.SQLITE3, CompressionMode.NONE)
    bag = tmp_path / "split"
    bag.mkdir()
    (a / "a.db3").rename(bag / "split_0.db3")
    (b / "b.db3").rename(bag / "split_1.db3")
    (bag / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n"
        "  relative_file_paths: [split_0.db3, split_1.db3]\n"
        "  compression_format: ''\n  compression_mode: ''\n"
    )
    with Ros2BagSource(bag) as src:
        counts = [(c.id, c.topic, c.count) for c in src.connections]
        # /sonar's definition differs between the files: two connections, one per file.
        assert counts == [
            (1, "/sonar", N),
            (2, "/odom", 20),
            (3, "/tf", 20),
            (4, "/tf_static", 2),
            (5, "/sonar", N),
        ]
        r = _ranges(src)
        assert len(r.range) == 2 * N
        # The first file carries variance (Jazzy definition), the second not (Humble).
        assert not np.isnan(r.variance[:N]).any() and np.isnan(r.variance[N:]).all()


RANGE_ROS1 = (
    "Header header\nuint8 ULTRASOUND=0\nuint8 INFRARED=1\nuint8 radiation_type\n"
    "float32 field_of_view\nfloat32 min_range\nfloat32 max_range\nfloat32 range\n"
    "================================================================================\n"
    "MSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id\n"
)


@pytest.mark.parametrize(
    "compression", [CompressionType.ZSTD, CompressionType.LZ4, CompressionType.NONE]
)
def test_mcap_library_file_ros1_and_cdr(tmp_path: Path, compression: CompressionType) -> None:
    path = tmp_path / "log.mcap"
    msgdef = JAZZY.generate_msgdef("sensor_msgs/msg/Range", ros_version=2)[0]
    with path.open("wb") as fh:
        w = McapWriter(fh, compression=compression, chunk_size=512)
        w.start(profile="ros2", library="test")
        s1 = w.register_schema("sensor_msgs/Range", "ros1msg", RANGE_ROS1.encode())
        s2 = w.register_schema("sensor_msgs/msg/Range", "ros2msg", msgdef.encode())
        c1 = w.register_channel("/sonar_ros1", "ros1", s1, {"md5sum": "abc"})
        c2 = w.register_channel("/sonar", "cdr", s2)
        c3 = w.register_channel("/json", "json", 0)
        for i in reversed(range(N)):  # written out of time order on purpose
            t = 10_000 + 100 * i
            w.add_message(
                c2,
                log_time=t,
                publish_time=t,
                sequence=i,
                data=bytes(JAZZY.serialize_cdr(_range(JAZZY, i), "sensor_msgs/msg/Range")),
            )
            w.add_message(c1, log_time=t, publish_time=t, sequence=i, data=b"\x00" * 8)
            w.add_message(c3, log_time=t, publish_time=t, sequence=i, data=b"{}")
        w.finish()
    with McapSource(path) as src:
        conns = {c.topic: c for c in src.connections}
        assert (conns["/sonar_ros1"].msgtype, conns["/sonar_ros1"].encoding) == (
            "sensor_msgs/msg/Range",
            "ros1",
        )
        assert conns["/sonar_ros1"].md5sum == "abc"
        assert conns["/sonar_ros1"].msgdef_format == "ros1msg"
        assert (conns["/json"].encoding, conns["/json"].msgtype) == ("other", "")
        assert {c.topic: c.count for c in src.connections} == {
            "/sonar_ros1": N,
            "/sonar": N,
            "/json": N,
        }
        batches = list(src.raw_batches([conns["/sonar"].id]))
        assert len(batches) > 1  # several chunks
        for b in batches:
            assert np.all(np.diff(b.log_time_ns) >= 0)
        starts = [int(b.log_time_ns[0]) for b in batches]
        assert starts == sorted(starts)
        r = _ranges(src)
        assert sorted(r.range.tolist()) == (0.125 * np.arange(N)).tolist()
        np.testing.assert_array_equal(r.variance, 0.25)
        assert src.warnings == []
