"""decode_ros1: vectorised fast paths against rosbags' deserializer, and bad messages."""

from __future__ import annotations

import math
from dataclasses import replace
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
    pose_stamped_msg,
    pwcs_msg,
    range_msg,
    store,
    tf_msg,
    write_bag,
)
from rosbags.highlevel import AnyReader

from formats.errors import FormatError
from formats.ros.columns import PoseColumns, RangeColumns, TransformColumns
from formats.ros.decode_ros1 import decode_ros1
from formats.ros.ros1bag import Ros1BagSource
from formats.ros.source import RawBatch


def _decode_topic(path: Path, topic: str) -> list[object]:
    with Ros1BagSource(path) as src:
        ids = [c.id for c in src.connections if c.topic == topic]
        return [decode_ros1(rb) for rb in src.raw_batches(ids)]


def test_tiago_range_matches_rosbags() -> None:
    (cols,) = _decode_topic(DATA / "tiago-sonar.bag", "/sonar_base")
    assert isinstance(cols, RangeColumns)
    with AnyReader([DATA / "tiago-sonar.bag"]) as ref:
        msgs: list[Any] = [ref.deserialize(d, c.msgtype) for c, _t, d in ref.messages()]
    assert cols.stamp_ns.shape == (609,)
    assert cols.stamp_ns.tolist() == [
        m.header.stamp.sec * NS + m.header.stamp.nanosec for m in msgs
    ]
    assert [cols.frames[c] for c in cols.frame] == [m.header.frame_id for m in msgs]
    assert sorted(cols.frames) == ["base_sonar_01_link", "base_sonar_02_link", "base_sonar_03_link"]
    assert cols.range.tolist() == [m.range for m in msgs]
    assert set(cols.field_of_view.tolist()) == {np.float32(0.5)}
    assert set(cols.min_range.tolist()) == {float(np.float32(0.02))}
    assert set(cols.max_range.tolist()) == {1.0}
    assert 0.65 < float(np.mean(cols.range >= cols.max_range)) < 0.75  # ~70 % no echo
    assert np.isnan(cols.variance).all()
    assert cols.radiation_type.tolist() == [m.radiation_type for m in msgs]


def test_range_groups_of_different_frame_lengths(tmp_path: Path) -> None:
    frames = ["a", "sonar_long_frame_name", "", "bb", "a"]
    msgs = [
        Msg(
            "/r",
            "sensor_msgs/msg/Range",
            NS + i,
            range_msg(NS + 100 + i, f, 0.25 * i, fov=0.1 * i, rmin=0.01, rmax=3.0 + i),
        )
        for i, f in enumerate(frames)
    ]
    (cols,) = _decode_topic(write_bag(tmp_path / "r.bag", msgs), "/r")
    assert isinstance(cols, RangeColumns)
    assert [cols.frames[c] for c in cols.frame] == frames
    assert cols.stamp_ns.tolist() == [NS + 100 + i for i in range(5)]
    assert cols.range.tolist() == [0.25 * i for i in range(5)]
    assert cols.field_of_view.tolist() == [float(np.float32(0.1 * i)) for i in range(5)]
    assert cols.max_range.tolist() == [3.0 + i for i in range(5)]


@pytest.mark.parametrize(
    ("msgtype", "make", "child"),
    [
        ("nav_msgs/msg/Odometry", odom_msg, True),
        ("geometry_msgs/msg/PoseStamped", pose_stamped_msg, False),
        ("geometry_msgs/msg/PoseWithCovarianceStamped", pwcs_msg, False),
    ],
)
def test_pose_types(tmp_path: Path, msgtype: str, make: Any, child: bool) -> None:
    frames = ["odom", "o", "odom", "world_frame"]
    msgs = []
    for i, f in enumerate(frames):
        kw = {"frame": f}
        if child:
            kw["child"] = "base_link" if i % 2 else "bl"
        msgs.append(
            Msg("/p", msgtype, NS + i, make(NS + 7 * i, 1.5 * i, -0.5 * i, 0.4 * i - 1.0, **kw))
        )
    (cols,) = _decode_topic(write_bag(tmp_path / "p.bag", msgs), "/p")
    assert isinstance(cols, PoseColumns)
    assert cols.stamp_ns.tolist() == [NS + 7 * i for i in range(4)]
    assert [cols.frames[c] for c in cols.frame] == frames
    expected_child = ["bl", "base_link", "bl", "base_link"] if child else [""] * 4
    assert [cols.frames[c] for c in cols.child] == expected_child
    assert cols.x.tolist() == [1.5 * i for i in range(4)]
    assert cols.y.tolist() == [-0.5 * i for i in range(4)]
    np.testing.assert_allclose(2 * np.arctan2(cols.qz, cols.qw), [0.4 * i - 1.0 for i in range(4)])


def test_tf_old_and_new(tmp_path: Path) -> None:
    (old,) = _decode_topic(DATA / "example-lz4.bag", "/tf")
    assert isinstance(old, TransformColumns)
    assert old.stamp_ns.shape == (2688,)
    assert sorted(
        {(old.frames[p], old.frames[c]) for p, c in zip(old.parent, old.child, strict=True)}
    ) == [
        ("world", "turtle1"),
        ("world", "turtle2"),
    ]
    msgs = [
        Msg(
            "/tf",
            "tf2_msgs/msg/TFMessage",
            NS,
            tf_msg(
                [
                    Tf(NS, "/odom", "base_link", 1.0, 2.0, 0.5),
                    Tf(NS + 1, "base_link", "s", 0.1, 0, 0),
                ]
            ),
        )
    ]
    (new,) = _decode_topic(write_bag(tmp_path / "tf.bag", msgs), "/tf")
    assert isinstance(new, TransformColumns)
    assert new.msg_index.tolist() == [0, 0]
    assert new.stamp_ns.tolist() == [NS, NS + 1]
    assert [new.frames[p] for p in new.parent] == ["odom", "base_link"]  # leading '/' dropped
    assert new.x.tolist() == [1.0, 0.1]
    assert new.z.tolist() == [0.3, 0.3]
    assert new.qz[0] == pytest.approx(math.sin(0.25))


def _range_raw(tmp_path: Path) -> RawBatch:
    msgs = [
        Msg("/r", "sensor_msgs/msg/Range", NS + i, range_msg(NS + i, "s", 1.0)) for i in range(3)
    ]
    with Ros1BagSource(write_bag(tmp_path / "r.bag", msgs)) as src:
        (raw,) = list(src.raw_batches([0]))
    return raw


def test_truncated_range_message(tmp_path: Path) -> None:
    raw = _range_raw(tmp_path)
    short = replace(raw, lengths=np.array([34, 33, 34], np.int64))
    with pytest.raises(
        FormatError, match=r"^message 1 of topic /r \(log time 1000000001 ns\): 33 bytes, a Range"
    ):
        decode_ros1(short)
    tiny = replace(raw, lengths=np.array([34, 34, 10], np.int64))
    with pytest.raises(
        FormatError, match=r"message 2 of topic /r .*10 bytes, too short for a header"
    ):
        decode_ros1(tiny)


def test_frame_length_overrun(tmp_path: Path) -> None:
    raw = _range_raw(tmp_path)
    buf = raw.buffer.copy()
    o = int(raw.offsets[0])
    buf[o + 12 : o + 16] = np.frombuffer(np.uint32(1_000_000).tobytes(), np.uint8)
    with pytest.raises(
        FormatError, match=r"message 0 of topic /r .*frame_id of 1000000 bytes overruns"
    ):
        decode_ros1(replace(raw, buffer=buf))


def test_malformed_tf_message(tmp_path: Path) -> None:
    msgs = [
        Msg(
            "/tf",
            "tf2_msgs/msg/TFMessage",
            NS,
            tf_msg([Tf(NS, "odom", "base_link", 1.0, 2.0, 0.5)]),
        )
    ]
    with Ros1BagSource(write_bag(tmp_path / "tf.bag", msgs)) as src:
        (raw,) = list(src.raw_batches([0]))
    with pytest.raises(
        FormatError,
        match=r"message 0 of topic /tf .*does not deserialize as tf2_msgs/msg/TFMessage",
    ):
        decode_ros1(replace(raw, lengths=raw.lengths - 20))


def test_unsupported_type(tmp_path: Path) -> None:
    string = store().types["std_msgs/msg/String"](data="x")
    with Ros1BagSource(
        write_bag(tmp_path / "s.bag", [Msg("/s", "std_msgs/msg/String", NS, string)])
    ) as src:
        (raw,) = list(src.raw_batches([0]))
    with pytest.raises(FormatError, match="topic /s: cannot decode type std_msgs/msg/String"):
        decode_ros1(raw)
