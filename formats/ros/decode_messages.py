"""What the ROS 1 and CDR decoders share: frame codes, error messages, and the
low-volume message types decoded one message at a time with rosbags' deserializers
(tf, PointCloud, p2os SonarArray, LaserScan). Only the deserialize call differs between
the encodings; everything after it is here once.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from formats.arrays import F64
from formats.errors import FormatError
from formats.ros.columns import (
    LASER_TYPES,
    POINTCLOUD_TYPES,
    SONARARRAY_TYPES,
    TF_TYPES,
    Columns,
    LaserScanColumns,
    PointColumns,
    SonarArrayColumns,
    TransformColumns,
)
from formats.ros.source import RawBatch

NS_PER_S = 1_000_000_000
# Bytes of the fixed-size float64 parts, the same in ROS 1 and CDR: a Pose is Point +
# Quaternion (7 f64), PoseWithCovariance adds 36 f64, a TwistWithCovariance is 6 + 36 f64.
POSE_BYTES = 7 * 8
POSE_COV_BYTES = POSE_BYTES + 36 * 8
TWIST_COV_BYTES = 6 * 8 + 36 * 8

_NS = 1_000_000_000


class FrameCodes:
    """Frame names → provisional codes; :meth:`finish` renumbers by first appearance."""

    def __init__(self) -> None:
        self.names: list[str] = []
        self._codes: dict[str, int] = {}

    def code(self, name: str) -> int:
        c = self._codes.get(name)
        if c is None:
            c = self._codes[name] = len(self.names)
            self.names.append(name)
        return c

    def finish(self, *columns: npt.NDArray[np.int32]) -> tuple[list[str], list[Any]]:
        """Codes renumbered in order of first appearance (row by row, columns in turn)."""
        if not self.names:
            return [], list(columns)
        inter = np.stack(columns, axis=1).reshape(-1) if columns[0].size else np.empty(0)
        present, first = np.unique(inter.astype(np.int64), return_index=True)
        order = present[np.argsort(first, kind="stable")]
        lut = np.full(len(self.names), -1, np.int32)  # names no row uses are dropped
        lut[order] = np.arange(order.size, dtype=np.int32)
        return [self.names[c] for c in order], [lut[c] for c in columns]


class MessageError(FormatError):
    """One message of a batch does not decode: ``index`` is its place in the batch (the
    reader skips it and records the loss)."""

    def __init__(self, message: str, index: int) -> None:
        super().__init__(message)
        self.index = index


def message_error(raw: RawBatch, i: int, what: str) -> MessageError:
    return MessageError(
        f"message {i} of topic {raw.connection.topic} "
        f"(log time {int(raw.log_time_ns[i])} ns): {what}", i
    )


def decode_per_message(raw: RawBatch) -> Columns | None:
    """Columns of a batch of a low-volume type (tf, PointCloud, SonarArray, LaserScan);
    ``None`` for any other type."""
    msgtype = raw.connection.msgtype
    if msgtype in TF_TYPES:
        return _decode_tf(raw)
    if msgtype in POINTCLOUD_TYPES:
        return _decode_pointcloud(raw)
    if msgtype in SONARARRAY_TYPES:
        return _decode_sonararray(raw)
    if msgtype in LASER_TYPES:
        return _decode_laserscan(raw)
    return None


def _deserialize(raw: RawBatch) -> list[Any]:
    # Imported here: typestores are only needed for the low-volume types.
    from formats.ros.typestore import typestore_for

    store = typestore_for(raw.connection)
    deserialize = store.deserialize_ros1 if raw.connection.encoding == "ros1" else store.deserialize_cdr
    msgtype = raw.connection.msgtype
    out: list[Any] = []
    for i in range(len(raw)):
        try:
            out.append(deserialize(raw.message(i), msgtype))
        # rosbags raises struct.error, IndexError, UnicodeDecodeError, ValueError, ... on
        # malformed bytes: every one of them means this message is corrupt.
        except Exception as err:
            raise message_error(raw, i, f"does not deserialize as {msgtype} ({err})") from err
    return out


def header_stamp(header: Any) -> int:
    return int(header.stamp.sec) * _NS + int(header.stamp.nanosec)


def _decode_tf(raw: RawBatch) -> TransformColumns:
    """tf2_msgs/TFMessage and the old tf/tfMessage: one row per transform."""
    frames = FrameCodes()
    idx: list[int] = []
    stamp: list[int] = []
    parent: list[int] = []
    childs: list[int] = []
    vals: list[tuple[float, ...]] = []
    for i, msg in enumerate(_deserialize(raw)):
        for tr in msg.transforms:
            t, q = tr.transform.translation, tr.transform.rotation
            idx.append(i)
            stamp.append(header_stamp(tr.header))
            # A leading '/' is tf1-era spelling of the same frame; tf2 strips it.
            parent.append(frames.code(tr.header.frame_id.lstrip("/")))
            childs.append(frames.code(tr.child_frame_id.lstrip("/")))
            vals.append((t.x, t.y, t.z, q.x, q.y, q.z, q.w))
    v = np.asarray(vals, np.float64).reshape(-1, 7)
    names, (p, c) = frames.finish(np.asarray(parent, np.int32), np.asarray(childs, np.int32))
    return TransformColumns(
        msg_index=np.asarray(idx, np.int64),
        stamp_ns=np.asarray(stamp, np.int64),
        parent=p,
        child=c,
        frames=names,
        x=v[:, 0].copy(),
        y=v[:, 1].copy(),
        z=v[:, 2].copy(),
        qx=v[:, 3].copy(),
        qy=v[:, 4].copy(),
        qz=v[:, 5].copy(),
        qw=v[:, 6].copy(),
    )


def _decode_pointcloud(raw: RawBatch) -> PointColumns:
    """sensor_msgs/msg/PointCloud: one row per point."""
    items = _deserialize(raw)
    frames = FrameCodes()
    per_msg = np.array([len(m.points) for m in items], np.int64)
    stamps = np.array([header_stamp(m.header) for m in items], np.int64)
    codes = np.array([frames.code(m.header.frame_id) for m in items], np.int32)
    xyz = np.array([(p.x, p.y, p.z) for m in items for p in m.points], np.float64)
    xyz = xyz.reshape(-1, 3)
    return PointColumns(
        msg_index=np.repeat(np.arange(len(raw), dtype=np.int64), per_msg),
        stamp_ns=np.repeat(stamps, per_msg),
        frame=np.repeat(codes, per_msg),
        frames=frames.names,
        x=xyz[:, 0].copy(),
        y=xyz[:, 1].copy(),
        z=xyz[:, 2].copy(),
        points_per_message=per_msg,
    )


def _decode_sonararray(raw: RawBatch) -> SonarArrayColumns:
    """p2os_msgs/msg/SonarArray (header, ranges_count, float64[] ranges): a row per value."""
    items = _deserialize(raw)
    frames = FrameCodes()
    ranges = [np.asarray(m.ranges, np.float64).reshape(-1) for m in items]
    per_msg = np.array([r.shape[0] for r in ranges], np.int64)
    stamps = np.array([header_stamp(m.header) for m in items], np.int64)
    codes = np.array([frames.code(m.header.frame_id) for m in items], np.int32)
    starts = np.cumsum(per_msg) - per_msg
    total = int(per_msg.sum())
    return SonarArrayColumns(
        msg_index=np.repeat(np.arange(len(raw), dtype=np.int64), per_msg),
        stamp_ns=np.repeat(stamps, per_msg),
        frame=np.repeat(codes, per_msg),
        frames=frames.names,
        index=np.arange(total, dtype=np.int64) - np.repeat(starts, per_msg),
        value=np.concatenate(ranges) if ranges else np.empty(0, np.float64),
        values_per_message=per_msg,
    )


def _decode_laserscan(raw: RawBatch) -> LaserScanColumns:
    """sensor_msgs/msg/LaserScan: per-message scalars, ranges concatenated."""
    items = _deserialize(raw)
    frames = FrameCodes()
    ranges = [np.asarray(m.ranges, np.float64).reshape(-1) for m in items]

    def col(name: str) -> F64:
        return np.array([float(getattr(m, name)) for m in items], np.float64)

    return LaserScanColumns(
        stamp_ns=np.array([header_stamp(m.header) for m in items], np.int64),
        frame=np.array([frames.code(m.header.frame_id) for m in items], np.int32),
        frames=frames.names,
        angle_min=col("angle_min"),
        angle_increment=col("angle_increment"),
        range_min=col("range_min"),
        range_max=col("range_max"),
        beams_per_message=np.array([r.shape[0] for r in ranges], np.int64),
        ranges=np.concatenate(ranges) if ranges else np.empty(0, np.float64),
    )
