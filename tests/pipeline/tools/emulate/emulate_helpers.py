"""Helpers of the emulate tests: synthetic laser logs and LaserScan bags written with rosbags."""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from formats.contract import SensorMount
from pipeline.tools.emulate import LaserLog

NS = 1_000_000_000
BASE = SensorMount(0.0, 0.0, 0.0)
REPO = Path(__file__).resolve().parents[4]
INTEL = REPO / "sample_logs" / "intel-lab" / "intel-corrected.log.gz"


def laser_log(
    ranges: npt.ArrayLike,
    angles_deg: npt.ArrayLike,
    *,
    poses: Sequence[tuple[float, float, float]] | None = None,
    mount: SensorMount = BASE,
    range_max: float = 30.0,
    range_min: float = 0.0,
) -> LaserLog:
    """A LaserLog of S scans sharing one set of beam angles (degrees), poses default 0."""
    r = np.asarray(ranges, np.float64)
    s = r.shape[0]
    a = np.broadcast_to(np.radians(np.asarray(angles_deg, np.float64)), r.shape).copy()
    p = np.zeros((s, 3)) if poses is None else np.asarray(poses, np.float64)
    return LaserLog(
        t_ns=(np.arange(s, dtype=np.int64) + 1) * NS,
        ranges=r,
        angles=a,
        range_min=np.full(s, range_min),
        range_max=np.full(s, range_max),
        x=p[:, 0].copy(),
        y=p[:, 1].copy(),
        yaw=p[:, 2].copy(),
        laser_mount=mount,
        parent_frame="map",
        child_frame="base_link",
        source_format="test",
    )


def wall_ranges(
    wall_x: float, angles_deg: np.ndarray, mount_x: float = 0.0, far: float = 81.83
) -> np.ndarray:
    """Laser ranges (from a laser at (mount_x, 0) facing +x) to the wall x = wall_x."""
    a = np.radians(angles_deg)
    with np.errstate(divide="ignore"):
        r = (wall_x - mount_x) / np.cos(a)
    return np.where((np.cos(a) > 1e-9) & (r < 50), r, far)


# ----------------------------------------------------------------------------- ROS bags


@lru_cache(maxsize=2)
def store(kind: str) -> Any:
    """rosbags typestore: Noetic (+ tf2_msgs/TFMessage) for 'ros1', Humble for 'ros2'."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if kind == "ros2":
        return get_typestore(Stores.ROS2_HUMBLE)
    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(
        get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage")
    )
    return ts


class Msgs:
    """Message builders of one typestore ('ros1' or 'ros2')."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.types = store(kind).types

    def _header(self, t_ns: int, frame: str) -> Any:
        stamp = self.types["builtin_interfaces/msg/Time"](sec=t_ns // NS, nanosec=t_ns % NS)
        if self.kind == "ros1":
            return self.types["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
        return self.types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def _quat(self, yaw: float) -> Any:
        return self.types["geometry_msgs/msg/Quaternion"](
            x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
        )

    def scan(
        self,
        t_ns: int,
        ranges: np.ndarray,
        angle_min: float,
        inc: float,
        frame: str = "laser",
        rmax: float = 30.0,
    ) -> Any:
        return self.types["sensor_msgs/msg/LaserScan"](
            header=self._header(t_ns, frame),
            angle_min=angle_min,
            angle_max=angle_min + inc * (len(ranges) - 1),
            angle_increment=inc,
            time_increment=0.0,
            scan_time=0.1,
            range_min=0.05,
            range_max=rmax,
            ranges=np.asarray(ranges, np.float32),
            intensities=np.zeros(0, np.float32),
        )

    def odom(self, t_ns: int, x: float, y: float, yaw: float) -> Any:
        T = self.types
        cov = np.zeros(36)
        vec = T["geometry_msgs/msg/Vector3"]
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0), orientation=self._quat(yaw)
        )
        twist = T["geometry_msgs/msg/Twist"](
            linear=vec(x=0.0, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)
        )
        return T["nav_msgs/msg/Odometry"](
            header=self._header(t_ns, "odom"),
            child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov),
        )

    def tf_static(self, t_ns: int, parent: str, child: str, x: float, y: float) -> Any:
        T = self.types
        tr = T["geometry_msgs/msg/TransformStamped"](
            header=self._header(t_ns, parent),
            child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=x, y=y, z=0.2),
                rotation=self._quat(0.0),
            ),
        )
        return T["tf2_msgs/msg/TFMessage"](transforms=[tr])


def write_bag(path: Path, kind: str, messages: Sequence[tuple[str, str, int, Any]]) -> Path:
    """A ROS 1 bag ('ros1') or a rosbag2 sqlite3 bag ('ros2') of (topic, ROS 2-style type,
    log time ns, message), written in the given order."""
    ts = store(kind)
    if kind == "ros1":
        from rosbags.rosbag1 import Writer as Writer1

        with Writer1(path) as w1:
            conns: dict[str, Any] = {}
            for topic, msgtype, _, _ in messages:
                if topic not in conns:
                    conns[topic] = w1.add_connection(topic, msgtype, typestore=ts)
            for topic, msgtype, t, msg in messages:
                w1.write(conns[topic], t, ts.serialize_ros1(msg, msgtype))
        return path
    from rosbags.rosbag2 import Writer as Writer2

    with Writer2(path, version=8) as w2:
        conns = {}
        for topic, msgtype, _, _ in messages:
            if topic not in conns:
                conns[topic] = w2.add_connection(topic, msgtype, typestore=ts)
        for topic, msgtype, t, msg in messages:
            w2.write(conns[topic], t, ts.serialize_cdr(msg, msgtype))
    return path
