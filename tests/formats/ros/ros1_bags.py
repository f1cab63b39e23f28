"""Test helpers: write ROS 1 bags with rosbags' writer (an independent implementation)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

DATA = Path(__file__).resolve().parents[2] / "data" / "ros1"
SONARARRAY_DEF = "Header header\nint32 ranges_count\nfloat64[] ranges"
NS = 1_000_000_000


@lru_cache(maxsize=1)
def store() -> Typestore:
    """ROS 1 Noetic types plus p2os_msgs/SonarArray."""
    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(get_types_from_msg(SONARARRAY_DEF, "p2os_msgs/msg/SonarArray"))
    tf_def = "geometry_msgs/TransformStamped[] transforms"
    ts.register(get_types_from_msg(tf_def, "tf2_msgs/msg/TFMessage"))
    return ts


def _t(cls: str) -> Any:
    return store().types[cls]


def header(t_ns: int, frame: str) -> Any:
    time = _t("builtin_interfaces/msg/Time")(sec=t_ns // NS, nanosec=t_ns % NS)
    return _t("std_msgs/msg/Header")(seq=0, stamp=time, frame_id=frame)


def quat(yaw: float) -> Any:
    return _t("geometry_msgs/msg/Quaternion")(
        x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
    )


def pose(x: float, y: float, yaw: float) -> Any:
    point = _t("geometry_msgs/msg/Point")(x=x, y=y, z=0.0)
    return _t("geometry_msgs/msg/Pose")(position=point, orientation=quat(yaw))


def range_msg(
    t_ns: int, frame: str, rng: float, fov: float = 0.5, rmin: float = 0.02, rmax: float = 4.0
) -> Any:
    return _t("sensor_msgs/msg/Range")(
        header=header(t_ns, frame),
        radiation_type=0,
        field_of_view=fov,
        min_range=rmin,
        max_range=rmax,
        range=rng,
    )


def odom_msg(
    t_ns: int, x: float, y: float, yaw: float, frame: str = "odom", child: str = "base_link"
) -> Any:
    cov = np.arange(36, dtype=np.float64)
    pwc = _t("geometry_msgs/msg/PoseWithCovariance")(pose=pose(x, y, yaw), covariance=cov)
    vec = _t("geometry_msgs/msg/Vector3")
    twist = _t("geometry_msgs/msg/Twist")(
        linear=vec(x=0.1, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.2)
    )
    twc = _t("geometry_msgs/msg/TwistWithCovariance")(twist=twist, covariance=cov)
    return _t("nav_msgs/msg/Odometry")(
        header=header(t_ns, frame), child_frame_id=child, pose=pwc, twist=twc
    )


def pose_stamped_msg(t_ns: int, x: float, y: float, yaw: float, frame: str = "map") -> Any:
    return _t("geometry_msgs/msg/PoseStamped")(header=header(t_ns, frame), pose=pose(x, y, yaw))


def pwcs_msg(t_ns: int, x: float, y: float, yaw: float, frame: str = "map") -> Any:
    pwc = _t("geometry_msgs/msg/PoseWithCovariance")(pose=pose(x, y, yaw), covariance=np.zeros(36))
    return _t("geometry_msgs/msg/PoseWithCovarianceStamped")(header=header(t_ns, frame), pose=pwc)


@dataclass
class Tf:
    """One transform: parent → child at t_ns, planar (x, y, yaw)."""

    t_ns: int
    parent: str
    child: str
    x: float
    y: float
    yaw: float


def tf_msg(transforms: Sequence[Tf]) -> Any:
    items = []
    for tr in transforms:
        trans = _t("geometry_msgs/msg/Vector3")(x=tr.x, y=tr.y, z=0.3)
        items.append(
            _t("geometry_msgs/msg/TransformStamped")(
                header=header(tr.t_ns, tr.parent),
                child_frame_id=tr.child,
                transform=_t("geometry_msgs/msg/Transform")(
                    translation=trans, rotation=quat(tr.yaw)
                ),
            )
        )
    return _t("tf2_msgs/msg/TFMessage")(transforms=items)


def pointcloud_msg(
    t_ns: int, points: Sequence[tuple[float, float]], frame: str = "base_link"
) -> Any:
    p32 = _t("geometry_msgs/msg/Point32")
    return _t("sensor_msgs/msg/PointCloud")(
        header=header(t_ns, frame),
        points=[p32(x=x, y=y, z=0.0) for x, y in points],
        channels=[],
    )


def sonararray_msg(t_ns: int, ranges: Sequence[float], frame: str = "base_link") -> Any:
    return _t("p2os_msgs/msg/SonarArray")(
        header=header(t_ns, frame),
        ranges_count=len(ranges),
        ranges=np.asarray(ranges, np.float64),
    )


@dataclass
class Msg:
    """A message to write: topic, ROS 2-style type, log time (ns), message object."""

    topic: str
    msgtype: str
    t_ns: int
    msg: Any


def write_bag(
    path: Path,
    messages: Sequence[Msg],
    *,
    compression: str = "none",
    chunk_threshold: int | None = None,
    extra_connections: int = 0,
) -> Path:
    """Write ``messages`` in the given order (log times need not be sorted).

    ``extra_connections`` adds that many more connections (other caller ids) to the first
    topic and spreads its messages over them round-robin.
    """
    writer = Writer(path)
    if compression == "bz2":
        writer.set_compression(Writer.CompressionFormat.BZ2)
    elif compression == "lz4":
        writer.set_compression(Writer.CompressionFormat.LZ4)
    if chunk_threshold is not None:
        writer.chunk_threshold = chunk_threshold
    ts = store()
    conns: dict[str, list[Any]] = {}
    with writer:
        for m in messages:
            if m.topic not in conns:
                n = 1 + (extra_connections if not conns else 0)
                conns[m.topic] = [
                    writer.add_connection(m.topic, m.msgtype, typestore=ts, callerid=f"/node{i}")
                    for i in range(n)
                ]
        counters = dict.fromkeys(conns, 0)
        for m in messages:
            group = conns[m.topic]
            conn = group[counters[m.topic] % len(group)]
            counters[m.topic] += 1
            writer.write(conn, m.t_ns, ts.serialize_ros1(m.msg, m.msgtype))
    return path
