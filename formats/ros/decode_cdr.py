"""Decode batches of ROS 2 CDR messages into columns (formats/ros/columns.py).

Range, Odometry, PoseStamped and PoseWithCovarianceStamped have vectorised fast paths:
every message starts with a 4-byte encapsulation header (byte 1 = 1: little-endian,
0: big-endian), then ``Header`` (int32 sec, uint32 nanosec, string frame_id as uint32
length incl. NUL + bytes). Fields after the frame id sit at offsets that depend only on
its length, so messages are grouped by that length and fixed fields gathered with numpy.
CDR aligns each primitive to its own size, counted from the end of the 4-byte header.
The other types are low-volume and go through rosbags' ``deserialize_cdr`` one by one.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import numpy.typing as npt

from formats.ros.columns import (
    LASER_TYPES,
    POINTCLOUD_TYPES,
    RANGE_TYPES,
    SONARARRAY_TYPES,
    TF_TYPES,
    Columns,
    LaserScanColumns,
    PointColumns,
    PoseColumns,
    RangeColumns,
    SonarArrayColumns,
    TransformColumns,
)
from formats.ros.source import Connection, RawBatch
from pipeline.errors import FormatError

I64 = npt.NDArray[np.int64]
F64 = npt.NDArray[np.float64]
_NS = 1_000_000_000
_ENCAP = 4  # encapsulation header bytes
_POSE = 7 * 8  # Point + Quaternion, float64
_POSE_COV = _POSE + 36 * 8
_TWIST_COV = 6 * 8 + 36 * 8


def decode_cdr(raw: RawBatch) -> Columns:
    """Columns of a batch of CDR messages of one of the DECODABLE_TYPES.

    Raises :class:`FormatError` ``"message N of topic T (...): ..."`` for a malformed
    message, a non-CDR encoding, or a type sonarmap does not decode.
    """
    conn = raw.connection
    if conn.encoding != "cdr":
        raise FormatError(
            f"topic {conn.topic}: message encoding {conn.encoding!r} is not CDR, cannot decode"
        )
    msgtype = conn.msgtype
    if msgtype in RANGE_TYPES:
        return _decode_range(raw)
    if msgtype == "nav_msgs/msg/Odometry":
        return _decode_pose(raw, child=True, tail=_POSE_COV + _TWIST_COV)
    if msgtype == "geometry_msgs/msg/PoseStamped":
        return _decode_pose(raw, child=False, tail=_POSE)
    if msgtype == "geometry_msgs/msg/PoseWithCovarianceStamped":
        return _decode_pose(raw, child=False, tail=_POSE_COV)
    if msgtype in TF_TYPES:
        return _decode_tf(raw)
    if msgtype in POINTCLOUD_TYPES:
        return _decode_pointcloud(raw)
    if msgtype in SONARARRAY_TYPES:
        return _decode_sonararray(raw)
    if msgtype in LASER_TYPES:
        return _decode_laserscan(raw)
    raise FormatError(f"topic {conn.topic}: cannot decode type {msgtype}")


def range_has_variance(connection: Connection) -> bool | None:
    """Whether the log's sensor_msgs/msg/Range definition has ``float32 variance``
    (ROS 2 Jazzy and later); None when the log carries no definition."""
    text = connection.msgdef
    if not text.strip():
        return None
    if connection.msgdef_format == "ros2idl":
        m = re.search(r"struct\s+Range\s*\{(.*?)\}", text, re.S)
        body = m.group(1) if m else text
        return re.search(r"^\s*float\s+variance\s*;", body, re.M) is not None
    main = re.split(r"^={10,}\s*$", text, maxsplit=1, flags=re.M)[0]
    return re.search(r"^\s*float32\s+variance\b", main, re.M) is not None


# --------------------------------------------------------------------------- helpers


class _Frames:
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


def _fail(raw: RawBatch, i: int, what: str) -> FormatError:
    return FormatError(
        f"message {i} of topic {raw.connection.topic} "
        f"(log time {int(raw.log_time_ns[i])} ns): {what}"
    )


def _check(raw: RawBatch, sel: npt.NDArray[np.intp], bad: npt.NDArray[np.bool_], what: str) -> None:
    """Raise for the first message of ``sel`` flagged ``bad``."""
    if bad.any():
        raise _fail(raw, int(sel[int(np.argmax(bad))]), what)


def _rows(buffer: npt.NDArray[np.uint8], pos: I64, width: int) -> npt.NDArray[np.uint8]:
    """``width`` bytes at each buffer position in ``pos`` as an (n, width) array."""
    if width == 0 or pos.size == 0:
        return np.empty((pos.shape[0], width), np.uint8)
    win = np.lib.stride_tricks.sliding_window_view(buffer, width)
    return np.asarray(win[pos])


def _field(rows: npt.NDArray[np.uint8], at: int, dtype: str) -> npt.NDArray[Any]:
    size = np.dtype(dtype).itemsize
    return np.ascontiguousarray(rows[:, at : at + size]).view(dtype).reshape(-1)


def _align(x: I64 | int, n: int) -> Any:
    return (x + (n - 1)) & ~(n - 1)


class _Header:
    """Byte order, stamp and frame id of every message, and where the rest begins."""

    def __init__(self, raw: RawBatch, frames: _Frames) -> None:
        n = len(raw)
        buf = raw.buffer
        self.start = raw.offsets.astype(np.int64) + _ENCAP  # CDR data start
        self.end = raw.offsets.astype(np.int64) + raw.lengths.astype(np.int64)
        all_ = np.arange(n)
        _check(raw, all_, raw.lengths < _ENCAP + 12, "too short for a CDR header")
        encap = _rows(buf, raw.offsets.astype(np.int64), 2)
        _check(
            raw,
            all_,
            (encap[:, 0] != 0) | (encap[:, 1] > 1),
            "unsupported CDR encapsulation (expected plain CDR, little or big endian)",
        )
        self.little = encap[:, 1] == 1
        self.stamp = np.empty(n, np.int64)
        self.frame = np.empty(n, np.int32)
        self.after = np.empty(n, np.int64)  # offset of the byte after frame_id, rel. start
        for order, sel in self.by_order():
            head = _rows(buf, self.start[sel], 12)
            sec = _field(head, 0, f"{order}i4").astype(np.int64)
            nsec = _field(head, 4, f"{order}u4").astype(np.int64)
            self.stamp[sel] = sec * _NS + nsec
            length = _field(head, 8, f"{order}u4").astype(np.int64)
            self.frame[sel] = _strings(
                raw, sel, self.start[sel] + 12, length, self.end[sel], frames, "frame_id"
            )
            self.after[sel] = 12 + length

    def by_order(self) -> list[tuple[str, npt.NDArray[np.intp]]]:
        """(numpy byte-order char, message indices) per byte order present."""
        out = []
        for order, mask in (("<", self.little), (">", ~self.little)):
            if mask.any():
                out.append((order, np.flatnonzero(mask)))
        return out


def _strings(
    raw: RawBatch,
    sel: npt.NDArray[np.intp],
    pos: I64,
    length: I64,
    end: I64,
    frames: _Frames,
    name: str,
) -> npt.NDArray[np.int32]:
    """Codes of the CDR strings (``length`` bytes incl. NUL at ``pos``), grouped by length."""
    _check(raw, sel, (length < 1) | (pos + length > end), f"{name} string runs past the end")
    codes = np.empty(sel.shape[0], np.int32)
    for ln in np.unique(length).tolist():
        grp = np.flatnonzero(length == ln)
        rows = _rows(raw.buffer, pos[grp], ln)
        _check(raw, sel[grp], rows[:, ln - 1] != 0, f"{name} string is not NUL-terminated")
        if ln == 1:
            codes[grp] = frames.code("")
            continue
        uniq, inv = _unique_rows(rows[:, : ln - 1])
        lut = []
        for k, u in enumerate(uniq):
            try:
                lut.append(frames.code(u.decode("utf-8")))
            except UnicodeDecodeError:
                bad = sel[grp][int(np.argmax(inv == k))]
                raise _fail(raw, int(bad), f"{name} is not UTF-8") from None
        codes[grp] = np.asarray(lut, np.int32)[inv]
    return codes


def _unique_rows(
    rows: npt.NDArray[np.uint8],
) -> tuple[list[bytes], npt.NDArray[np.intp]]:
    """Distinct byte rows (in sorted order of their hash) and each row's index into them.

    Rows are hashed to one uint64 (numpy's hash-based unique on integers is much faster
    than sorting void rows), then checked against their representative; any collision
    falls back to the exact void-row unique.
    """
    n, width = rows.shape
    pad = -width % 8
    words = np.zeros((n, width + pad), np.uint8)
    words[:, :width] = rows
    cols = words.view("<u8")
    key = cols[:, 0].copy()
    for k in range(1, cols.shape[1]):
        key = key * np.uint64(0x100000001B3) ^ cols[:, k]
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    if np.array_equal(rows, rows[first[inv]]):
        return [rows[i].tobytes() for i in first], inv
    block = np.ascontiguousarray(rows).view(f"V{width}").reshape(-1)
    uniq, inv = np.unique(block, return_inverse=True)
    return [bytes(u) for u in uniq], inv.reshape(-1)


# --------------------------------------------------------------------------- fast paths


def _decode_range(raw: RawBatch) -> RangeColumns:
    """sensor_msgs/msg/Range: uint8 radiation_type, then float32 fov, min, max, range
    [, variance] aligned to 4 after the frame id."""
    n = len(raw)
    frames = _Frames()
    hdr = _Header(raw, frames)
    declared = range_has_variance(raw.connection)
    rad = np.empty(n, np.uint8)
    vals = np.full((n, 5), np.nan, np.float64)
    for order, sel in hdr.by_order():
        floats_at = _align(hdr.after[sel] + 1, 4)
        avail = hdr.end[sel] - hdr.start[sel] - floats_at
        has_var = avail >= 20 if declared is None else np.full(sel.shape[0], declared)
        need = np.where(has_var, 20, 16)
        _check(raw, sel, avail < need, "too short for sensor_msgs/msg/Range")
        rad[sel] = raw.buffer[hdr.start[sel] + hdr.after[sel]]
        rows = _rows(raw.buffer, hdr.start[sel] + floats_at, 16)
        for k in range(4):
            vals[sel, k] = _field(rows, 4 * k, f"{order}f4")
        if has_var.any():
            vsel = np.flatnonzero(has_var)
            vrows = _rows(raw.buffer, hdr.start[sel][vsel] + floats_at[vsel] + 16, 4)
            vals[sel[vsel], 4] = _field(vrows, 0, f"{order}f4")
    names, (frame,) = frames.finish(hdr.frame)
    return RangeColumns(
        stamp_ns=hdr.stamp,
        frame=frame,
        frames=names,
        radiation_type=rad,
        field_of_view=vals[:, 0].copy(),
        min_range=vals[:, 1].copy(),
        max_range=vals[:, 2].copy(),
        range=vals[:, 3].copy(),
        variance=vals[:, 4].copy(),
    )


def _decode_pose(raw: RawBatch, *, child: bool, tail: int) -> PoseColumns:
    """Odometry (header, child_frame_id, pose, twist), PoseStamped, PoseWithCovarianceStamped:
    position and orientation are the first 7 float64 after the strings, aligned to 8."""
    n = len(raw)
    frames = _Frames()
    hdr = _Header(raw, frames)
    childs = np.full(n, 0 if child else frames.code(""), np.int32)
    vals = np.empty((n, 7), np.float64)
    for order, sel in hdr.by_order():
        start, end = hdr.start[sel], hdr.end[sel]
        after = hdr.after[sel]
        if child:
            at = _align(after, 4)
            _check(raw, sel, start + at + 4 > end, "too short for child_frame_id")
            length = _field(_rows(raw.buffer, start + at, 4), 0, f"{order}u4").astype(np.int64)
            childs[sel] = _strings(raw, sel, start + at + 4, length, end, frames, "child_frame_id")
            after = at + 4 + length
        pose_at = _align(after, 8)
        _check(raw, sel, start + pose_at + tail > end, f"too short for {raw.connection.msgtype}")
        rows = _rows(raw.buffer, start + pose_at, _POSE)
        for k in range(7):
            vals[sel, k] = _field(rows, 8 * k, f"{order}f8")
    names, (frame, child_codes) = frames.finish(hdr.frame, childs)
    return PoseColumns(
        stamp_ns=hdr.stamp,
        frame=frame,
        child=child_codes,
        frames=names,
        x=vals[:, 0].copy(),
        y=vals[:, 1].copy(),
        z=vals[:, 2].copy(),
        qx=vals[:, 3].copy(),
        qy=vals[:, 4].copy(),
        qz=vals[:, 5].copy(),
        qw=vals[:, 6].copy(),
    )


# --------------------------------------------------------------------------- rosbags path


def _deserialize(raw: RawBatch) -> list[Any]:
    # Imported here: typestores are only needed for the low-volume types.
    from formats.ros.typestore import typestore_for

    store = typestore_for(raw.connection)
    msgtype = raw.connection.msgtype
    out: list[Any] = []
    for i in range(len(raw)):
        try:
            out.append(store.deserialize_cdr(raw.message(i), msgtype))
        # rosbags raises struct.error, IndexError, UnicodeDecodeError, ValueError, ... on
        # malformed bytes: every one of them means this message is corrupt.
        except Exception as err:
            raise _fail(raw, i, f"does not deserialize as {msgtype} ({err})") from err
    return out


def _header_stamp(header: Any) -> int:
    return int(header.stamp.sec) * _NS + int(header.stamp.nanosec)


def _decode_tf(raw: RawBatch) -> TransformColumns:
    """tf2_msgs/msg/TFMessage: one row per transform."""
    frames = _Frames()
    idx: list[int] = []
    stamp: list[int] = []
    parent: list[int] = []
    childs: list[int] = []
    vals: list[tuple[float, ...]] = []
    for i, msg in enumerate(_deserialize(raw)):
        for tr in msg.transforms:
            t, q = tr.transform.translation, tr.transform.rotation
            idx.append(i)
            stamp.append(_header_stamp(tr.header))
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
    frames = _Frames()
    per_msg = np.array([len(m.points) for m in items], np.int64)
    stamps = np.array([_header_stamp(m.header) for m in items], np.int64)
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
    frames = _Frames()
    ranges = [np.asarray(m.ranges, np.float64).reshape(-1) for m in items]
    per_msg = np.array([r.shape[0] for r in ranges], np.int64)
    stamps = np.array([_header_stamp(m.header) for m in items], np.int64)
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
    frames = _Frames()
    ranges = [np.asarray(m.ranges, np.float64).reshape(-1) for m in items]

    def col(name: str) -> F64:
        return np.array([float(getattr(m, name)) for m in items], np.float64)

    return LaserScanColumns(
        stamp_ns=np.array([_header_stamp(m.header) for m in items], np.int64),
        frame=np.array([frames.code(m.header.frame_id) for m in items], np.int32),
        frames=frames.names,
        angle_min=col("angle_min"),
        angle_increment=col("angle_increment"),
        range_min=col("range_min"),
        range_max=col("range_max"),
        beams_per_message=np.array([r.shape[0] for r in ranges], np.int64),
        ranges=np.concatenate(ranges) if ranges else np.empty(0, np.float64),
    )
