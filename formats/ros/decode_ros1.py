"""Decode batches of ROS 1 serialized messages into columns.

Fast paths (Range, Odometry, PoseStamped, PoseWithCovarianceStamped): a ROS 1 message is
its fields packed little-endian without padding, so once the lengths of its strings
(``frame_id``, ``child_frame_id``) are known its layout is fixed. Messages are grouped by
those lengths (a handful of groups: one per frame-name length), each group is gathered
into a 2-D ``uint8`` array (one row per message, via a sliding-window view of the chunk
buffer) and read through a structured dtype — no Python loop over messages.

The low-volume types (tf, PointCloud, SonarArray, LaserScan) are deserialized one
message at a time with rosbags and the log's own message definitions.
"""

from __future__ import annotations

from collections.abc import Callable
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
from formats.ros.source import RawBatch


def decode_ros1(raw: RawBatch) -> Columns:
    """Columns of a batch of ROS 1 messages of one of the DECODABLE_TYPES.

    Raises :class:`FormatError` ``"message N of topic T: ..."`` for a malformed message
    and for a type sonarmap does not decode.
    """
    msgtype = raw.connection.msgtype
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
        raise FormatError(f"topic {raw.connection.topic}: cannot decode type {msgtype}")
    return columns


# --------------------------------------------------------------------------- helpers


def _check(raw: RawBatch, bad: npt.NDArray[np.bool_], what: Callable[[int], str]) -> None:
    """Raise for the first message flagged ``bad``."""
    if bad.any():
        i = int(np.argmax(bad))
        raise message_error(raw, i, what(i))


def _gather(buf: npt.NDArray[np.uint8], pos: I64, dtype: np.dtype[Any]) -> np.ndarray:
    """One ``dtype`` item read at each byte position ``pos`` of ``buf`` (callers check the
    bounds). A view of the buffer with a 1-byte stride makes this one fancy-index copy."""
    n = buf.shape[0] - dtype.itemsize + 1
    if n <= 0 or pos.shape[0] == 0:
        return np.zeros(pos.shape[0], dtype)
    items = np.ndarray(shape=(n,), dtype=dtype, buffer=buf, strides=(1,))
    return items[pos]


_U32 = np.dtype("<u4")


def _u32_at(raw: RawBatch, pos: I64) -> I64:
    """u32 little-endian at buffer positions ``pos`` (callers check the bounds)."""
    return _gather(raw.buffer, pos, _U32).astype(np.int64)


def _codes(block: np.ndarray, frames: FrameCodes) -> npt.NDArray[np.int32]:
    """Codes of fixed-length strings (a ``V<L>`` array) in ``frames``.

    Strings are hashed to uint64 (few distinct values: one per sensor), the hash is
    checked to be collision-free, and only the distinct values become Python strings.
    """
    n = block.shape[0]
    length = block.dtype.itemsize
    width = -(-length // 8) * 8
    raw = np.zeros((n, width), np.uint8)
    raw[:, :length] = np.ascontiguousarray(block).view(np.uint8).reshape(n, length)
    words = raw.view("<u8")
    h = words[:, 0].copy()
    for k in range(1, words.shape[1]):
        h = h * np.uint64(0x100000001B3) ^ words[:, k]
    _u, first, inv = np.unique(h, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    if not np.array_equal(words, words[first][inv]):  # pragma: no cover - hash collision
        _u, first, inv = np.unique(
            np.ascontiguousarray(block), return_index=True, return_inverse=True
        )
        inv = inv.reshape(-1)
    names = [raw[i, :length].tobytes().decode("utf-8", "replace") for i in first]
    for j in np.argsort(first):  # register in order of first appearance: stable sensor ids
        frames.code(names[j])
    lut = np.array([frames.code(name) for name in names], dtype=np.int32)
    return lut[inv]


def _string_field(name: str, offset: int, length: int) -> list[tuple[str, str, int]]:
    """A structured-dtype field for a string's bytes (none for an empty string)."""
    return [(name, f"V{length}", offset)] if length else []


def _stamp(rec: np.ndarray) -> I64:
    return rec["sec"].astype(np.int64) * NS_PER_S + rec["nsec"].astype(np.int64)


def _struct(width: int, fields: list[tuple[str, str, int]]) -> np.dtype[Any]:
    return np.dtype(
        {
            "names": [f[0] for f in fields],
            "formats": [f[1] for f in fields],
            "offsets": [f[2] for f in fields],
            "itemsize": width,
        }
    )


def _groups(key: I64) -> list[tuple[int, npt.NDArray[np.intp]]]:
    """(key value, message indices) per distinct key (few: one per string length)."""
    if key.shape[0] and key.min() == key.max():  # the common case: no sort needed
        return [(int(key[0]), np.arange(key.shape[0]))]
    uniq, inv = np.unique(key, return_inverse=True)
    if uniq.shape[0] == 1:
        return [(int(uniq[0]), np.arange(key.shape[0]))]
    order = np.argsort(inv, kind="stable")
    bounds = np.searchsorted(inv[order], np.arange(uniq.shape[0] + 1))
    return [(int(u), order[bounds[g] : bounds[g + 1]]) for g, u in enumerate(uniq)]


def _frame_lengths(raw: RawBatch) -> I64:
    """Length of ``header.frame_id`` of every message (header = seq, stamp, frame_id)."""
    _check(raw, raw.lengths < 16, lambda i: f"{int(raw.lengths[i])} bytes, too short for a header")
    n1 = _u32_at(raw, raw.offsets + 12)
    _check(
        raw,
        n1 > raw.lengths - 16,
        lambda i: f"frame_id of {int(n1[i])} bytes overruns the {int(raw.lengths[i])}-byte message",
    )
    return n1


# --------------------------------------------------------------------------- fast paths


def _decode_range(raw: RawBatch) -> RangeColumns:
    """sensor_msgs/Range: header, u8 radiation_type, f32 fov, min_range, max_range, range."""
    n = len(raw)
    n1 = _frame_lengths(raw)
    need = 33 + n1
    _check(
        raw,
        raw.lengths != need,
        lambda i: f"{int(raw.lengths[i])} bytes, a Range with this frame_id has {int(need[i])}",
    )
    frames = FrameCodes()
    stamp = np.empty(n, np.int64)
    frame = np.empty(n, np.int32)
    rad = np.empty(n, np.uint8)
    cols = {k: np.empty(n, np.float64) for k in ("fov", "min", "max", "range")}
    for length, idx in _groups(n1):
        p = 16 + length
        width = p + 17
        dt = _struct(
            width,
            [
                ("sec", "<u4", 4),
                ("nsec", "<u4", 8),
                ("rad", "u1", p),
                ("fov", "<f4", p + 1),
                ("min", "<f4", p + 5),
                ("max", "<f4", p + 9),
                ("range", "<f4", p + 13),
                *_string_field("s1", 16, length),
            ],
        )
        rec = _gather(raw.buffer, raw.offsets[idx], dt)
        stamp[idx] = _stamp(rec)
        frame[idx] = _codes(rec["s1"], frames) if length else frames.code("")
        rad[idx] = rec["rad"]
        for k, col in cols.items():
            col[idx] = rec[k]
    return RangeColumns(
        stamp_ns=stamp,
        frame=frame,
        frames=frames.names,
        radiation_type=rad,
        field_of_view=cols["fov"],
        min_range=cols["min"],
        max_range=cols["max"],
        range=cols["range"],
        variance=np.full(n, np.nan),
    )


def _decode_pose(raw: RawBatch, *, child: bool, tail: int) -> PoseColumns:
    """Odometry (child=True), PoseStamped, PoseWithCovarianceStamped: header,
    [child_frame_id], then a Pose (position, orientation) and ``tail - 56`` more bytes."""
    n = len(raw)
    n1 = _frame_lengths(raw)
    if child:
        _check(
            raw,
            raw.lengths < 20 + n1,
            lambda i: f"{int(raw.lengths[i])} bytes, too short for child_frame_id",
        )
        n2 = _u32_at(raw, raw.offsets + 16 + n1)
        need = 20 + n1 + n2 + tail
    else:
        n2 = np.zeros(n, np.int64)
        need = 16 + n1 + tail
    _check(
        raw,
        raw.lengths != need,
        lambda i: (
            f"{int(raw.lengths[i])} bytes, expected {int(need[i])} for "
            f"{raw.connection.msgtype} with these frame ids"
        ),
    )
    frames = FrameCodes()
    empty = frames.code("")
    stamp = np.empty(n, np.int64)
    frame = np.empty(n, np.int32)
    child_code = np.full(n, empty, np.int32)
    names = ("x", "y", "z", "qx", "qy", "qz", "qw")
    cols = {k: np.empty(n, np.float64) for k in names}
    key = (n1 << 32) | n2
    for k, idx in _groups(key):
        l1, l2 = k >> 32, k & 0xFFFFFFFF
        p = 16 + l1 + (4 + l2 if child else 0)
        width = p + tail
        dt = _struct(
            width,
            [("sec", "<u4", 4), ("nsec", "<u4", 8)]
            + [(name, "<f8", p + 8 * j) for j, name in enumerate(names)]
            + _string_field("s1", 16, l1)
            + (_string_field("s2", 20 + l1, l2) if child else []),
        )
        rec = _gather(raw.buffer, raw.offsets[idx], dt)
        stamp[idx] = _stamp(rec)
        frame[idx] = _codes(rec["s1"], frames) if l1 else frames.code("")
        if child:
            child_code[idx] = _codes(rec["s2"], frames) if l2 else empty
        for name in names:
            cols[name][idx] = rec[name]
    return PoseColumns(
        stamp_ns=stamp,
        frame=frame,
        child=child_code,
        frames=frames.names,
        **cols,
    )


# --------------------------------------------------------------------------- per message
