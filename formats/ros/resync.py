"""Finding the next record after damaged framing (ROS 1 bags, MCAP files).

A record walk finds each record from the length of the one before, so one garbage length
or header would end it there and lose the rest of the log. After such damage the walk
searches forward for the next offset where a plausible record starts and goes on from
there: the bytes in between are lost (counted), everything after them is read.

The search reads the file in windows of :data:`WINDOW` bytes — memory stays bounded
whatever the file or its damage declares — keeps in each window, with numpy, the offsets
whose first bytes could start a record (:func:`ros1_candidates`, :func:`mcap_candidates`:
a length that fits in the file, a first header byte or an opcode the format uses) and
hands those, in file order, to the format's full check (the reader's ``accept``: a header
that parses with the fields its opcode needs, a chunk that inflates and matches its CRC,
...). The first offset that passes is the next record; None when none is left.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

__all__ = ["WINDOW", "mcap_candidates", "next_record", "ros1_candidates"]

WINDOW = 1 << 18  # bytes searched per read
_LOOKAHEAD = 16  # bytes past the window a candidate's first fields need

# A ROS 1 record header this long or longer is not taken when resynchronising (the
# biggest real ones, connection headers, hold a topic name and a few ids).
ROS1_MAX_HEADER = 1 << 16
# First letters of the header field names of rosbag 2.0 records (op, conn, count, topic,
# compression, size, ver, time, chunk_pos, start_time, end_time, index_pos, ...).
_ROS1_FIELD_FIRST = np.frombuffer(b"cehiostv", np.uint8)

Candidates = Callable[[npt.NDArray[np.uint8], int, int], npt.NDArray[np.int64]]


def _uint_at(buf: npt.NDArray[np.uint8], count: int, dtype: str) -> npt.NDArray[np.uint64]:
    """A view of the ``dtype`` values starting at byte 0..count-1 of ``buf`` (1-byte
    stride: no copy)."""
    return np.ndarray(shape=(count,), dtype=dtype, buffer=buf, strides=(1,))


def _room(count: int, remaining: int, head: int) -> npt.NDArray[np.int64]:
    """Bytes left after a ``head``-byte record head at offsets 0..count-1 (may be < 0)."""
    return remaining - head - np.arange(count, dtype=np.int64)


def ros1_candidates(buf: npt.NDArray[np.uint8], n: int, remaining: int) -> npt.NDArray[np.int64]:
    """Offsets < ``n`` of ``buf`` where a ROS 1 record could start: a header length in
    [8, ROS1_MAX_HEADER], a first field of at least 4 bytes inside it whose name starts
    with a letter a rosbag field name starts with, all within ``remaining`` bytes."""
    m = min(n, buf.shape[0] - 8)
    if m <= 0:
        return np.empty(0, np.int64)
    hlen = _uint_at(buf, m, "<u4")
    first = _uint_at(buf[4:], m, "<u4")
    ok = (hlen >= 8) & (hlen <= ROS1_MAX_HEADER) & (first >= 4) & (first <= hlen - 4)
    ok &= np.isin(buf[8 : 8 + m], _ROS1_FIELD_FIRST)
    at = np.flatnonzero(ok)
    return at[hlen[at].astype(np.int64) <= _room(m, remaining, 8)[at]]


def mcap_candidates(
    ops: npt.NDArray[np.uint8],
) -> Candidates:
    """The candidate finder for MCAP records of opcodes ``ops``: an opcode byte among
    them followed by a u64 length whose record ends within ``remaining`` bytes."""

    def find(buf: npt.NDArray[np.uint8], n: int, remaining: int) -> npt.NDArray[np.int64]:
        m = min(n, buf.shape[0] - 8)
        if m <= 0:
            return np.empty(0, np.int64)
        at = np.flatnonzero(np.isin(buf[:m], ops))
        room = _room(m, remaining, 9)[at]
        at, room = at[room >= 0], room[room >= 0]
        # Compared as uint64: a garbage length near 2**64 must not wrap or round.
        return at[_uint_at(buf[1:], m, "<u8")[at] <= room.astype(np.uint64)]

    return find


def next_record(
    read_at: Callable[[int, int], bytes],
    start: int,
    size: int,
    candidates: Candidates,
    accept: Callable[[int], bool],
) -> int | None:
    """The first offset >= ``start`` of a file of ``size`` bytes where ``accept`` takes a
    record, trying only the ``candidates`` of each window; None when there is none."""
    pos = start
    while pos < size:
        n = min(WINDOW, size - pos)
        data = read_at(pos, n + _LOOKAHEAD)
        buf = np.frombuffer(data, np.uint8)
        for off in candidates(buf, n, size - pos).tolist():
            at = pos + int(off)
            if accept(at):
                return at
        pos += n
    return None
