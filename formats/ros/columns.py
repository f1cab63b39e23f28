"""Decoded message columns: what the decoders of every encoding produce per message type.

One row per message (per transform / point / value for the ragged types), numpy arrays
throughout. Strings that repeat (frame ids) are returned as codes into a small list
(``frames``) so there is no Python object per message.
Types with a vectorised fast path: Range, Odometry (and the pose types). The rest may be
decoded per message with rosbags' deserializers: they are low-volume.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from formats.arrays import F64, I32, I64


@dataclass(frozen=True)
class RangeColumns:
    """sensor_msgs/Range."""

    stamp_ns: I64
    frame: I32  # code into frames
    frames: list[str]
    radiation_type: npt.NDArray[np.uint8]
    field_of_view: F64
    min_range: F64
    max_range: F64
    range: F64
    variance: F64  # ROS 2 (Jazzy+) Range.variance; NaN when the type has none


@dataclass(frozen=True)
class PoseColumns:
    """nav_msgs/Odometry, geometry_msgs/PoseStamped, PoseWithCovarianceStamped.

    ``child`` codes the Odometry child_frame_id; for the other types it is the code of ''.
    """

    stamp_ns: I64
    frame: I32
    child: I32
    frames: list[str]
    x: F64
    y: F64
    z: F64
    qx: F64
    qy: F64
    qz: F64
    qw: F64


@dataclass(frozen=True)
class TransformColumns:
    """tf2_msgs/TFMessage and the old tf/tfMessage: one row per transform.

    ``msg_index`` is the index of the message within the batch each transform came from.
    """

    msg_index: I64
    stamp_ns: I64
    parent: I32
    child: I32
    frames: list[str]
    x: F64
    y: F64
    z: F64
    qx: F64
    qy: F64
    qz: F64
    qw: F64


@dataclass(frozen=True)
class PointColumns:
    """sensor_msgs/PointCloud (RosAria sonar): one row per point, in message order."""

    msg_index: I64
    stamp_ns: I64  # per point (the message's stamp)
    frame: I32
    frames: list[str]
    x: F64
    y: F64
    z: F64
    points_per_message: I64  # one entry per message


@dataclass(frozen=True)
class SonarArrayColumns:
    """p2os_msgs/SonarArray: one row per value (``index`` = position in ``ranges``)."""

    msg_index: I64
    stamp_ns: I64
    frame: I32
    frames: list[str]
    index: I64
    value: F64
    values_per_message: I64


@dataclass(frozen=True)
class LaserScanColumns:
    """sensor_msgs/LaserScan: per-message scalars, and ranges as one row per beam."""

    stamp_ns: I64  # per message
    frame: I32  # per message
    frames: list[str]
    angle_min: F64
    angle_increment: F64
    range_min: F64
    range_max: F64
    beams_per_message: I64
    ranges: F64  # concatenated over messages


Columns = (
    RangeColumns
    | PoseColumns
    | TransformColumns
    | PointColumns
    | SonarArrayColumns
    | LaserScanColumns
)

# ROS 2-style names of the types sonarmap interprets, and what each is used for.
RANGE_TYPES = {"sensor_msgs/msg/Range"}
POSE_TYPES = {
    "nav_msgs/msg/Odometry",
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
}
TF_TYPES = {"tf2_msgs/msg/TFMessage", "tf/msg/tfMessage"}
POINTCLOUD_TYPES = {"sensor_msgs/msg/PointCloud"}
SONARARRAY_TYPES = {"p2os_msgs/msg/SonarArray"}
LASER_TYPES = {"sensor_msgs/msg/LaserScan"}
DECODABLE_TYPES = (
    RANGE_TYPES | POSE_TYPES | TF_TYPES | POINTCLOUD_TYPES | SONARARRAY_TYPES | LASER_TYPES
)
