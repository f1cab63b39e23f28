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

from formats.arrays import I64
from formats.errors import FormatError
from formats.ros.columns import (
    RANGE_TYPES,
    Columns,
    PoseColumns,
    RangeColumns,
)
from formats.ros.decode_messages import (
    NS_PER_S,
    POSE_BYTES,
    POSE_COV_BYTES,
    TWIST_COV_BYTES,
    FrameCodes,
    decode_per_message,
    message_error,
)
from formats.ros.source import Connection, RawBatch

_ENCAP = 4  # encapsulation header bytes


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
        return _decode_pose(raw, child=True, tail=POSE_COV_BYTES + TWIST_COV_BYTES)
    if msgtype == "geometry_msgs/msg/PoseStamped":
        return _decode_pose(raw, child=False, tail=POSE_BYTES)
    if msgtype == "geometry_msgs/msg/PoseWithCovarianceStamped":
        return _decode_pose(raw, child=False, tail=POSE_COV_BYTES)
    columns = decode_per_message(raw)
    if columns is None:
        raise FormatError(f"topic {conn.topic}: cannot decode type {msgtype}")
    return columns


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


def _check(raw: RawBatch, sel: npt.NDArray[np.intp], bad: npt.NDArray[np.bool_], what: str) -> None:
    """Raise for the first message of ``sel`` flagged ``bad``."""
    if bad.any():
        raise message_error(raw, int(sel[int(np.argmax(bad))]), what)


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

    def __init__(self, raw: RawBatch, frames: FrameCodes) -> None:
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
            self.stamp[sel] = sec * NS_PER_S + nsec
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
    frames: FrameCodes,
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
                raise message_error(raw, int(bad), f"{name} is not UTF-8") from None
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
    frames = FrameCodes()
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
    frames = FrameCodes()
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
        rows = _rows(raw.buffer, start + pose_at, POSE_BYTES)
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
