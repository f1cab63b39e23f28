"""Write sonar logs in every format sonarmap reads, with the formats' own libraries.

``write_log(content, path, fmt)`` writes a :class:`LogContent` (ranges, odometry poses and
sensor mounts) as:

* ``ros1`` — a ROS 1 bag (``rosbags.rosbag1.Writer``; chunks none/bz2/lz4),
* ``ros2`` / ``ros2-mcap`` — a rosbag2 directory, sqlite3 or MCAP storage
  (``rosbags.rosbag2.Writer``, Humble types),
* ``mcap`` / ``mcap-ros1`` — a standalone MCAP file (``mcap.writer.Writer``), ``cdr`` with
  ``ros2msg`` schemas or ``ros1`` with ``ros1msg`` schemas (chunks none/lz4/zstd),
* ``csv`` / ``csv-set`` — the single-file and the set layout of sonarmap's CSV schema.

ROS logs carry ``/sonar`` (sensor_msgs/Range, frame_id = sensor name, one message per
reading), ``/odom`` (nav_msgs/Odometry, ``parent → child``) and ``/tf_static``
(tf2_msgs/TFMessage, base frame → each sensor frame, at the first stamp). Messages are
written in time order; log time = header stamp. None of the formats embeds wall-clock
time here, so the same content gives the same bytes. ``variance`` is not written: Humble's
Range and the CSV schema have no such field.
"""

from __future__ import annotations

import functools
import math
import shutil
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
import numpy.typing as npt

from formats.angles import wrap_angle
from formats.arrays import F64, I64
from formats.contract import PoseBatch, RangeBatch, SensorMount
from formats.errors import ConfigError, OutputError
from formats.stamps import ROS_TIME_END_NS, format_time_s, ros_stamps_fit

FORMATS: tuple[str, ...] = ("ros1", "ros2", "ros2-mcap", "mcap", "mcap-ros1", "csv", "csv-set")
_COMPRESSION: dict[str, tuple[str, ...]] = {
    "ros1": ("none", "bz2", "lz4"),
    "mcap": ("none", "lz4", "zstd"),
    "mcap-ros1": ("none", "lz4", "zstd"),
    # rosbag2 file-level compression: each storage file becomes <name>.zstd.
    "ros2": ("none", "zstd"),
    "ros2-mcap": ("none", "zstd"),
}

RANGE_TOPIC = "/sonar"
ODOM_TOPIC = "/odom"
TF_STATIC_TOPIC = "/tf_static"
RANGE_TYPE = "sensor_msgs/msg/Range"
ODOM_TYPE = "nav_msgs/msg/Odometry"
TF_TYPE = "tf2_msgs/msg/TFMessage"


@dataclass(frozen=True)
class LogContent:
    """What a log holds, as columns.

    ``ranges``: one row per reading (``sensor_id`` indexes ``sensor_names``; fov, min and
    max range per reading, rad/m; ``scan_id`` ≥ 0 is written to CSV as ``scan``).
    ``poses``: ``poses.parent_frame → poses.child_frame`` (odom → base_link), m/rad.
    ``mounts``: sensor name → mount in the base frame (``poses.child_frame``).
    """

    ranges: RangeBatch
    sensor_names: tuple[str, ...]
    poses: PoseBatch
    mounts: dict[str, SensorMount]


def write_log(
    content: LogContent, path: str | Path, fmt: str, *, compression: str = "none"
) -> Path:
    """Write ``content`` to ``path`` as ``fmt`` (one of FORMATS); return the path.

    Refuses an existing path (OutputError); a writer that fails half-way removes what it
    wrote. ``compression``: chunk compression for ros1 (none/bz2/lz4) and mcap
    (none/lz4/zstd); the other formats take only 'none'.
    """
    p = Path(path)
    if fmt not in FORMATS:
        raise ConfigError(f"unknown log format '{fmt}' (known: {', '.join(FORMATS)})")
    allowed = _COMPRESSION.get(fmt, ("none",))
    if compression not in allowed:
        raise ConfigError(f"format '{fmt}' takes compression {list(allowed)}, got {compression!r}")
    if p.exists() or p.is_symlink():
        raise OutputError("exists already, not overwriting", p)
    if not p.parent.is_dir():
        raise OutputError("parent directory does not exist", p)
    _check(content)
    _check_stamps(content, fmt, p)
    writer: Callable[[LogContent, Path, str, str], None] = {
        "ros1": _write_ros1,
        "ros2": _write_ros2,
        "ros2-mcap": _write_ros2,
        "mcap": _write_mcap,
        "mcap-ros1": _write_mcap,
        "csv": _write_csv_single,
        "csv-set": _write_csv_set,
    }[fmt]
    refused: tuple[type[Exception], ...] = (OSError, *_library_errors())
    try:
        writer(content, p, fmt, compression)
    except OutputError:
        _remove(p)
        raise
    except refused as err:
        # What the file system or a library writer refuses becomes a one-line OutputError.
        _remove(p)
        raise OutputError(f"cannot write {fmt} log: {err}", p) from err
    return p


def _library_errors() -> tuple[type[Exception], ...]:
    from mcap.exceptions import McapError
    from rosbags.rosbag1 import WriterError as Rosbag1Error
    from rosbags.rosbag2 import WriterError as Rosbag2Error

    return (Rosbag1Error, Rosbag2Error, McapError)


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p)
    elif p.exists():
        p.unlink()


def _check(c: LogContent) -> None:
    r = c.ranges
    if len(r) and (int(r.sensor_id.min()) < 0 or int(r.sensor_id.max()) >= len(c.sensor_names)):
        raise ConfigError("ranges.sensor_id must index sensor_names")
    if len(c.poses) == 0 and len(r) == 0:
        raise ConfigError("log content is empty (no ranges, no poses)")


def _check_stamps(c: LogContent, fmt: str, p: Path) -> None:
    """Refuse stamps a ROS or MCAP log cannot hold (:func:`formats.stamps.ros_stamps_fit`:
    every stamp here is also a log time); CSV holds any."""
    if fmt in ("csv", "csv-set"):
        return
    t = np.concatenate([c.poses.t_ns, c.ranges.t_ns]).astype(np.int64)
    if len(t) and not ros_stamps_fit(int(t.min()), int(t.max()), log_time=True):
        raise OutputError(
            f"stamps {t.min() / 1e9:.3f} … {t.max() / 1e9:.3f} s cannot be written as {fmt}: "
            f"its stamps hold 0 … {ROS_TIME_END_NS // 1_000_000_000 - 1} s (ROS 2's int32 "
            "seconds)", p)


# --------------------------------------------------------------------------- event order


def _events(c: LogContent) -> tuple[int, I64, I64, I64]:
    """(tf_static stamp, kind per event 0=odom 1=range, row index, stamp ns), time order.

    Ties keep odometry before ranges and each stream in its own order (stable sort).
    """
    t = np.concatenate([c.poses.t_ns, c.ranges.t_ns]).astype(np.int64)
    kind = np.concatenate([np.zeros(len(c.poses), np.int64), np.ones(len(c.ranges), np.int64)])
    row = np.concatenate([np.arange(len(c.poses)), np.arange(len(c.ranges))]).astype(np.int64)
    order = np.lexsort((row, kind, t))
    t0 = int(t.min())
    return t0, kind[order], row[order], t[order]


def _range_order(c: LogContent) -> I64:
    return np.argsort(c.ranges.t_ns, kind="stable").astype(np.int64)


# --------------------------------------------------------------------------- serialization


def serialize_ranges(c: LogContent, encoding: str) -> tuple[npt.NDArray[np.uint8], I64, I64]:
    """All Range messages, serialized at once: (buffer, offsets, lengths) per reading.

    ``encoding`` is 'cdr' (ROS 2 Humble layout) or 'ros1' (header ``seq`` = the reading's
    rank in time order). Byte-identical to rosbags' serializers (tested), but vectorised:
    one numpy record array per sensor name instead of one message object per reading.
    """
    r = c.ranges
    n = len(r)
    seq = np.empty(n, np.int64)
    seq[_range_order(c)] = np.arange(n)
    sec, nsec = np.divmod(r.t_ns, np.int64(1_000_000_000))
    names = [s.encode() for s in c.sensor_names]
    size = np.array([_range_layout(len(b), encoding)[1] for b in names], np.int64)
    lengths = size[r.sensor_id] if n else np.empty(0, np.int64)
    offsets = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64) if n else lengths
    buf = np.zeros(int(lengths.sum()), np.uint8)
    for j, nb in enumerate(names):
        idx = np.nonzero(r.sensor_id == j)[0]
        if idx.size == 0:
            continue
        dtype, itemsize = _range_layout(len(nb), encoding)
        rec = np.zeros(idx.size, dtype)
        if encoding == "cdr":
            rec["encap"] = np.frombuffer(b"\x00\x01\x00\x00", np.uint8)
        else:
            rec["seq"] = seq[idx]
        rec["sec"] = sec[idx]
        rec["nsec"] = nsec[idx]
        rec["len"] = len(nb) + (1 if encoding == "cdr" else 0)
        if nb:
            rec["name"] = np.frombuffer(nb, np.uint8)
        rec["rad"] = 0  # ULTRASOUND
        rec["fov"] = r.fov_rad[idx]
        rec["min"] = r.min_range_m[idx]
        rec["max"] = r.max_range_m[idx]
        rec["range"] = r.range_m[idx]
        raw = rec.view(np.uint8).reshape(idx.size, itemsize)
        buf[offsets[idx, None] + np.arange(itemsize)[None, :]] = raw
    return buf, offsets, lengths


def _range_layout(name_len: int, encoding: str) -> tuple[np.dtype[Any], int]:
    if encoding == "cdr":
        # 4-byte encapsulation header; CDR aligns relative to the byte after it.
        after_name = 12 + name_len + 1  # sec, nanosec, length, bytes + NUL
        rad = 4 + after_name
        floats = 4 + ((after_name + 1 + 3) // 4) * 4
        fields: dict[str, Any] = {
            "names": ["encap", "sec", "nsec", "len", "name", "rad", "fov", "min", "max", "range"],
            "formats": [
                ("u1", 4),
                "<i4",
                "<u4",
                "<u4",
                ("u1", max(name_len, 1)),
                "u1",
                "<f4",
                "<f4",
                "<f4",
                "<f4",
            ],
            "offsets": [0, 4, 8, 12, 16, rad, floats, floats + 4, floats + 8, floats + 12],
        }
        itemsize = floats + 16
    else:
        rad = 16 + name_len
        fields = {
            "names": ["seq", "sec", "nsec", "len", "name", "rad", "fov", "min", "max", "range"],
            "formats": [
                "<u4",
                "<u4",
                "<u4",
                "<u4",
                ("u1", max(name_len, 1)),
                "u1",
                "<f4",
                "<f4",
                "<f4",
                "<f4",
            ],
            "offsets": [0, 4, 8, 12, 16, rad, rad + 1, rad + 5, rad + 9, rad + 13],
        }
        itemsize = rad + 17
    if name_len == 0:
        # An empty frame_id has no bytes to hold.
        for key in ("names", "formats", "offsets"):
            del fields[key][4]
    fields["itemsize"] = itemsize
    return np.dtype(cast(Any, fields)), itemsize


@functools.cache
def typestore(encoding: str) -> Any:
    """rosbags typestore of an encoding: Noetic for 'ros1' (plus tf2_msgs/TFMessage, which
    rosbags' Noetic store lacks), Humble for 'cdr'."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if encoding != "ros1":
        return get_typestore(Stores.ROS2_HUMBLE)
    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF_TYPE))
    return ts


class _Serializer:
    """Odometry and TFMessage objects of one typestore (few messages: per object)."""

    def __init__(self, encoding: str) -> None:
        self.encoding = encoding
        self.ts = typestore(encoding)
        self.T = self.ts.types

    def _header(self, t_ns: int, frame: str, seq: int) -> Any:
        sec, nsec = divmod(int(t_ns), 1_000_000_000)
        stamp = self.T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
        if self.encoding == "ros1":
            return self.T["std_msgs/msg/Header"](seq=seq, stamp=stamp, frame_id=frame)
        return self.T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def _ser(self, msg: Any, msgtype: str) -> bytes:
        if self.encoding == "ros1":
            return bytes(self.ts.serialize_ros1(msg, msgtype))
        return bytes(self.ts.serialize_cdr(msg, msgtype))

    def odometry(self, c: LogContent) -> Iterator[bytes]:
        """Odometry per pose, in row order (zero twist, zero covariance)."""
        T = self.T
        p = c.poses
        zero36 = np.zeros(36, np.float64)
        twist = T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](
                linear=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
            ),
            covariance=zero36,
        )
        qz, qw = np.sin(p.yaw / 2), np.cos(p.yaw / 2)
        for i in range(len(p)):
            pose = T["geometry_msgs/msg/PoseWithCovariance"](
                pose=T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](x=float(p.x[i]), y=float(p.y[i]), z=0.0),
                    orientation=T["geometry_msgs/msg/Quaternion"](
                        x=0.0, y=0.0, z=float(qz[i]), w=float(qw[i])
                    ),
                ),
                covariance=zero36,
            )
            msg = T[ODOM_TYPE](
                header=self._header(int(p.t_ns[i]), p.parent_frame, i),
                child_frame_id=p.child_frame,
                pose=pose,
                twist=twist,
            )
            yield self._ser(msg, ODOM_TYPE)

    def tf_static(self, c: LogContent, t_ns: int) -> bytes:
        """One TFMessage: base frame → each sensor frame (z = 0), sorted by sensor name."""
        T = self.T
        base = c.poses.child_frame
        transforms = []
        for name in sorted(c.mounts):
            m = c.mounts[name]
            transforms.append(
                T["geometry_msgs/msg/TransformStamped"](
                    header=self._header(t_ns, base, 0),
                    child_frame_id=name,
                    transform=T["geometry_msgs/msg/Transform"](
                        translation=T["geometry_msgs/msg/Vector3"](x=m.x, y=m.y, z=0.0),
                        rotation=T["geometry_msgs/msg/Quaternion"](
                            x=0.0, y=0.0, z=math.sin(m.yaw / 2), w=math.cos(m.yaw / 2)
                        ),
                    ),
                )
            )
        return self._ser(T[TF_TYPE](transforms=transforms), TF_TYPE)


def _messages(c: LogContent, encoding: str) -> Iterator[tuple[str, int, bytes]]:
    """(topic, stamp ns, serialized bytes) of the whole log, in time order."""
    ser = _Serializer(encoding)
    t0, kind, row, t = _events(c)
    if c.mounts:
        yield TF_STATIC_TOPIC, t0, ser.tf_static(c, t0)
    odom = list(ser.odometry(c))
    buf, off, length = serialize_ranges(c, encoding)
    mv = memoryview(buf.data)
    for k, i, stamp in zip(kind.tolist(), row.tolist(), t.tolist(), strict=True):
        if k == 0:
            yield ODOM_TOPIC, stamp, odom[i]
        else:
            o = int(off[i])
            yield RANGE_TOPIC, stamp, bytes(mv[o : o + int(length[i])])


# --------------------------------------------------------------------------- ROS writers


def _write_ros1(c: LogContent, path: Path, fmt: str, compression: str) -> None:
    from rosbags.rosbag1 import Writer

    ts = typestore("ros1")
    writer = Writer(path)
    if compression != "none":
        writer.set_compression(Writer.CompressionFormat[compression.upper()])
    with writer:
        conns = {
            TF_STATIC_TOPIC: writer.add_connection(
                TF_STATIC_TOPIC, TF_TYPE, typestore=ts, callerid="/sonarmap_sim", latching=1
            ),
            ODOM_TOPIC: writer.add_connection(
                ODOM_TOPIC, ODOM_TYPE, typestore=ts, callerid="/sonarmap_sim"
            ),
            RANGE_TOPIC: writer.add_connection(
                RANGE_TOPIC, RANGE_TYPE, typestore=ts, callerid="/sonarmap_sim"
            ),
        }
        for topic, stamp, data in _messages(c, "ros1"):
            writer.write(conns[topic], stamp, data)


def _write_ros2(c: LogContent, path: Path, fmt: str, compression: str) -> None:
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    ts = typestore("cdr")
    plugin = StoragePlugin.MCAP if fmt == "ros2-mcap" else StoragePlugin.SQLITE3
    forever = QosTime(sec=9223372036, nsec=854775807)  # rclcpp's "infinite" duration

    def qos(durability: QosDurability) -> Qos:
        return Qos(
            QosHistory.KEEP_LAST,
            1 if durability == QosDurability.TRANSIENT_LOCAL else 10,
            QosReliability.RELIABLE,
            durability,
            forever,
            forever,
            QosLiveliness.AUTOMATIC,
            forever,
            False,
        )

    writer = Writer(path, version=9, storage_plugin=plugin)
    if compression == "zstd":
        writer.set_compression(CompressionMode.FILE, CompressionFormat.ZSTD)
    writer.open()
    try:
        conns = {
            TF_STATIC_TOPIC: writer.add_connection(
                TF_STATIC_TOPIC,
                TF_TYPE,
                typestore=ts,
                offered_qos_profiles=[qos(QosDurability.TRANSIENT_LOCAL)],
            ),
            ODOM_TOPIC: writer.add_connection(
                ODOM_TOPIC,
                ODOM_TYPE,
                typestore=ts,
                offered_qos_profiles=[qos(QosDurability.VOLATILE)],
            ),
            RANGE_TOPIC: writer.add_connection(
                RANGE_TOPIC,
                RANGE_TYPE,
                typestore=ts,
                offered_qos_profiles=[qos(QosDurability.VOLATILE)],
            ),
        }
        for topic, stamp, data in _messages(c, "cdr"):
            writer.write(conns[topic], stamp, data)
    finally:
        writer.close()


def _write_mcap(c: LogContent, path: Path, fmt: str, compression: str) -> None:
    from mcap.writer import CompressionType, Writer

    ros1 = fmt == "mcap-ros1"
    ts = typestore("ros1" if ros1 else "cdr")
    comp = {"none": CompressionType.NONE, "lz4": CompressionType.LZ4, "zstd": CompressionType.ZSTD}[
        compression
    ]
    with path.open("xb") as stream:
        writer = Writer(stream, compression=comp)
        writer.start(profile="ros1" if ros1 else "ros2", library="sonarmap log_writers")
        channels: dict[str, int] = {}
        for topic, msgtype in (
            (TF_STATIC_TOPIC, TF_TYPE),
            (ODOM_TOPIC, ODOM_TYPE),
            (RANGE_TOPIC, RANGE_TYPE),
        ):
            if ros1:
                msgdef, md5 = ts.generate_msgdef(msgtype)
                name = msgtype.replace("/msg/", "/")
                sid = writer.register_schema(name, "ros1msg", msgdef.encode())
                meta = {"md5sum": md5, "callerid": "/sonarmap_sim"}
                if topic == TF_STATIC_TOPIC:
                    meta["latching"] = "1"
                channels[topic] = writer.register_channel(topic, "ros1", sid, meta)
            else:
                msgdef, _ = ts.generate_msgdef(msgtype, ros_version=2)
                sid = writer.register_schema(msgtype, "ros2msg", msgdef.encode())
                channels[topic] = writer.register_channel(topic, "cdr", sid, {})
        seq = dict.fromkeys(channels, 0)
        for topic, stamp, data in _messages(c, "ros1" if ros1 else "cdr"):
            writer.add_message(channels[topic], stamp, data, stamp, seq[topic])
            seq[topic] += 1
        writer.finish()


# --------------------------------------------------------------------------- CSV writers


def _f(a: npt.ArrayLike) -> list[str]:
    # repr of a Python float round-trips exactly; inf, -inf and nan as the schema allows.
    return [repr(v) for v in np.asarray(a, dtype=np.float64).tolist()]


def _pose_at(p: PoseBatch, t_ns: I64) -> tuple[F64, F64, F64]:
    """Logged pose at each stamp: linear in x, y and unwrapped yaw, held at the ends."""
    if len(p) == 0:
        raise ConfigError("the csv layout needs poses: the log content has none")
    o = np.argsort(p.t_ns, kind="stable")
    # Relative int64 first: epoch nanoseconds as float64 lose ~256 ns of precision.
    base = p.t_ns[o[0]]
    tp = (p.t_ns[o] - base).astype(np.float64)
    t = (t_ns - base).astype(np.float64)
    yaw = np.interp(t, tp, np.unwrap(p.yaw[o]))
    yaw = wrap_angle(yaw)
    return np.interp(t, tp, p.x[o]), np.interp(t, tp, p.y[o]), yaw


def _write_rows(path: Path, header: list[str], cols: list[list[str]]) -> None:
    lines = [",".join(header)]
    lines += [",".join(row) for row in zip(*cols, strict=True)]
    with path.open("x", encoding="utf-8", newline="") as f:
        f.write("\n".join(lines) + "\n")


def _range_cols(
    c: LogContent, order: I64, *, limits: bool = True
) -> tuple[list[str], list[list[str]]]:
    r = c.ranges
    names = np.array(c.sensor_names, dtype=object)
    header = ["sensor", "range"]
    cols = [names[r.sensor_id[order]].tolist(), _f(r.range_m[order])]
    if limits:
        header += ["fov", "min_range", "max_range"]
        cols += [_f(r.fov_rad[order]), _f(r.min_range_m[order]), _f(r.max_range_m[order])]
    if len(r) and bool((r.scan_id >= 0).any()):
        header.append("scan")
        cols.append([str(v) for v in r.scan_id[order].tolist()])
    return header, cols


def _limits_per_sensor(c: LogContent) -> bool:
    """Whether fov, min and max range are constant per sensor (so sensors.csv holds them)."""
    r = c.ranges
    if len(r) == 0:
        return True
    _, first = np.unique(r.sensor_id, return_index=True)
    lookup = np.zeros(int(r.sensor_id.max()) + 1, dtype=np.int64)
    lookup[r.sensor_id[first]] = first
    ref = lookup[r.sensor_id]
    return all(
        np.array_equal(col, col[ref], equal_nan=True)
        for col in (r.fov_rad, r.min_range_m, r.max_range_m)
    )


def _check_names(c: LogContent) -> None:
    bad = [n for n in c.sensor_names if not n or any(ch in n for ch in ',"\n\r#') or n != n.strip()]
    if bad:
        raise ConfigError(f"sensor names cannot be written to CSV as is: {bad!r}")


def _write_csv_single(c: LogContent, path: Path, fmt: str, compression: str) -> None:
    """One row per reading: ``t,x,y,yaw,sensor,range,fov,min_range,max_range[,scan]``."""
    _check_names(c)
    order = _range_order(c)
    t = c.ranges.t_ns[order]
    x, y, yaw = _pose_at(c.poses, t)
    header, cols = _range_cols(c, order)
    _write_rows(
        path, ["t", "x", "y", "yaw", *header], [format_time_s(t), _f(x), _f(y), _f(yaw), *cols]
    )


def _write_csv_set(c: LogContent, path: Path, fmt: str, compression: str) -> None:
    """A directory with ranges.csv, poses.csv and sensors.csv (mounts in the base frame)."""
    _check_names(c)
    path.mkdir()
    order = _range_order(c)
    # Limits that never change per sensor live in sensors.csv only (a third of the size).
    header, cols = _range_cols(c, order, limits=not _limits_per_sensor(c))
    _write_rows(path / "ranges.csv", ["t", *header], [format_time_s(c.ranges.t_ns[order]), *cols])
    p = c.poses
    po = np.argsort(p.t_ns, kind="stable")
    _write_rows(
        path / "poses.csv",
        ["t", "x", "y", "yaw"],
        [format_time_s(p.t_ns[po]), _f(p.x[po]), _f(p.y[po]), _f(p.yaw[po])],
    )
    # Beam limits per sensor from its first reading (NaN for a sensor without readings).
    r = c.ranges
    names = list(c.sensor_names) + sorted(set(c.mounts) - set(c.sensor_names))
    rows: list[list[str]] = []
    for j, name in enumerate(names):
        m = c.mounts.get(name)
        hit = np.nonzero(r.sensor_id == j)[0] if j < len(c.sensor_names) else np.empty(0, int)
        lim = (
            [math.nan] * 3
            if hit.size == 0
            else [
                float(r.fov_rad[hit[0]]),
                float(r.min_range_m[hit[0]]),
                float(r.max_range_m[hit[0]]),
            ]
        )
        pose = [math.nan] * 3 if m is None else [m.x, m.y, m.yaw]
        rows.append([name, *[repr(float(v)) for v in (*pose, *lim)]])
    _write_rows(
        path / "sensors.csv",
        ["sensor", "x", "y", "yaw", "fov", "min_range", "max_range"],
        [list(col) for col in zip(*rows, strict=True)] if rows else [[] for _ in range(7)],
    )
