"""Standalone MCAP files (and the MCAP storage of ROS 2 bags) as a :class:`MessageSource`.

The summary section (schemas, channels, statistics, chunk indexes) is read with a small
parser of our own; messages are located through the per-chunk Message Index records and
gathered with numpy over the decompressed chunk, so there is no Python work per message.
Files without a usable summary (not finalised, truncated) are read by a linear scan of
their intact records; what is lost is reported in :attr:`McapSource.warnings`.

Record layout (https://mcap.dev/spec): ``opcode u8, length u64, content``; little-endian
integers, strings and byte arrays prefixed by a u32 length, maps by a u32 byte length.
"""

from __future__ import annotations

import array
import contextlib
import struct
import zlib
from collections.abc import Collection, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from formats.errors import FormatError
from formats.magic import MCAP_MAGIC
from formats.ros.inflate import MAX_CHUNK_BYTES, ChunkError, inflate
from formats.ros.resync import mcap_candidates, next_record
from formats.ros.source import (
    Connection,
    Encoding,
    FileSource,
    RawBatch,
    SourceAccessors,
    normalize_msgtype,
)
from formats.storage.location import Location, as_location

OP_HEADER = 0x01
OP_FOOTER = 0x02
OP_SCHEMA = 0x03
OP_CHANNEL = 0x04
OP_MESSAGE = 0x05
OP_CHUNK = 0x06
OP_MESSAGE_INDEX = 0x07
OP_CHUNK_INDEX = 0x08
OP_STATISTICS = 0x0B
OP_DATA_END = 0x0F
# Opcodes the spec defines (0x01-0x10); 0x80-0xFF are applications' own records (skipped),
# anything else is damage.
_LAST_OPCODE = 0x10
_APPLICATION_OPCODES = 0x80
# The longest chunk record taken: its compressed records (never longer than what they
# inflate to, MAX_CHUNK_BYTES, plus an eighth) and its fields; longer is damage.
_MAX_CHUNK_RECORD = MAX_CHUNK_BYTES + (MAX_CHUNK_BYTES >> 3) + (1 << 16)
# Where the walk resynchronises after damage: the records of a data section.
_RESYNC_OPS = np.array([OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_MESSAGE_INDEX,
                        OP_DATA_END], np.uint8)

_RECORD_HEAD = 9  # opcode u8 + length u64
_MESSAGE_HEAD = 22  # channel_id u16, sequence u32, log_time u64, publish_time u64
_FOOTER_LEN = _RECORD_HEAD + 20
# Top-level messages outside chunks are grouped into blocks of about this many bytes.
_LOOSE_BLOCK_BYTES = 4 << 20
_U64 = struct.Struct("<Q")
# A record length seen this many times in a row starts a vectorised run (see _walk).
_RUN_START = 4


def encoding_of(message_encoding: str) -> Encoding:
    """Our encoding name for an MCAP channel ``message_encoding``."""
    if message_encoding in ("ros1", "cdr"):
        return message_encoding  # type: ignore[return-value]
    return "other"


class _Short(Exception):
    """A record's content ends before one of its fields (internal)."""


class _Cursor:
    """Little-endian field reader over one record's content."""

    __slots__ = ("data", "end", "pos")

    def __init__(self, data: bytes | memoryview, pos: int = 0, end: int | None = None) -> None:
        self.data = data
        self.pos = pos
        self.end = len(data) if end is None else end

    def _take(self, n: int) -> int:
        p = self.pos
        if p + n > self.end:
            raise _Short
        self.pos = p + n
        return p

    def u16(self) -> int:
        return int(struct.unpack_from("<H", self.data, self._take(2))[0])

    def u32(self) -> int:
        return int(struct.unpack_from("<I", self.data, self._take(4))[0])

    def u64(self) -> int:
        return int(struct.unpack_from("<Q", self.data, self._take(8))[0])

    def raw(self, n: int) -> bytes:
        p = self._take(n)
        return bytes(self.data[p : p + n])

    def string(self) -> str:
        try:
            return self.raw(self.u32()).decode()
        except UnicodeDecodeError as err:
            raise _Short from err

    def str_map(self) -> dict[str, str]:
        n = self.u32()
        stop = self.pos + n
        if stop > self.end:
            raise _Short
        out: dict[str, str] = {}
        while self.pos < stop:
            key = self.string()
            out[key] = self.string()
        return out

    def u16_u64_map(self) -> dict[int, int]:
        n = self.u32()
        if n % 10 or self.pos + n > self.end:
            raise _Short
        out: dict[int, int] = {}
        for _ in range(n // 10):
            key = self.u16()
            out[key] = self.u64()
        return out


@dataclass
class _Schema:
    id: int
    name: str
    encoding: str
    data: str


@dataclass
class _Channel:
    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict[str, str]


@dataclass
class _Block:
    """A run of records to parse: a chunk's records or top-level records of the file.

    ``record_offset`` is where the chunk record (or the first loose record) starts in the
    file; ``msg_index`` maps channel id → (file offset, length) of its Message Index record,
    empty when the block has none (then the records are walked one by one).
    """

    start_ns: int
    end_ns: int
    record_offset: int
    record_length: int
    is_chunk: bool
    msg_index: dict[int, int] = field(default_factory=dict)
    index_region: tuple[int, int] = (0, 0)  # offset, length of the block's message indexes
    counts: dict[int, int] = field(default_factory=dict)  # per channel, when known


def _parse_schema(c: _Cursor) -> _Schema | None:
    sid = c.u16()
    name = c.string()
    enc = c.string()
    data = c.raw(c.u32())
    if sid == 0:
        return None  # id 0 means "no schema" and may not be defined
    return _Schema(sid, name, enc, data.decode("utf-8", errors="replace"))


def _parse_channel(c: _Cursor) -> _Channel:
    cid = c.u16()
    sid = c.u16()
    topic = c.string()
    enc = c.string()
    meta = c.str_map()
    return _Channel(cid, sid, topic, enc, meta)


def _walk(
    buf: bytes | memoryview | npt.NDArray[np.uint8], start: int, stop: int
) -> tuple[npt.NDArray[np.int64], int]:
    """Offsets of the complete records in ``buf[start:stop]`` (int64, 8 bytes per record,
    no Python object per record), and where the walk ended.

    A record's place depends on the one before, so the walk is a Python step per record,
    except along a run of records of one length (a topic's fixed-size messages, or the
    9-byte empty records of a bomb): once a length repeats, the next records are guessed
    at that stride and checked with numpy, as many as hold the same length.
    """
    arr = np.frombuffer(buf, np.uint8)
    view = arr.data
    parts: list[npt.NDArray[np.int64]] = []
    found = array.array("q")
    unpack = _U64.unpack_from
    pos, prev, repeats = start, -1, 0
    while pos + _RECORD_HEAD <= stop:
        (length,) = unpack(view, pos + 1)
        nxt = pos + _RECORD_HEAD + length
        if nxt > stop:
            break
        found.append(pos)
        pos = nxt
        repeats = repeats + 1 if length == prev else 0
        prev = length
        if repeats >= _RUN_START:
            run = _same_length_run(arr, pos, stop, length)
            if run.size:
                parts += [np.array(found, np.int64), run]
                found = array.array("q")
                pos = int(run[-1]) + _RECORD_HEAD + length
            repeats = 0
    parts.append(np.array(found, np.int64))
    return (parts[0] if len(parts) == 1 else np.concatenate(parts)), pos


def _same_length_run(
    arr: npt.NDArray[np.uint8], pos: int, stop: int, length: int
) -> npt.NDArray[np.int64]:
    """Offsets of the records from ``pos`` on that each have ``length`` (consecutive,
    complete, up to the first of another length)."""
    step = _RECORD_HEAD + length
    out: list[npt.NDArray[np.int64]] = []
    window = 1024
    while True:
        k = min(window, (stop - pos) // step)
        if k <= 0:
            break
        at = pos + step * np.arange(k, dtype=np.int64)
        same = _u64_at(arr, at + 1) == length
        n = k if same.all() else int(np.argmin(same))
        out.append(at[:n])
        if n < k:
            break
        pos += step * k
        window = min(window * 4, 1 << 22)
    return np.concatenate(out) if out else np.empty(0, np.int64)


def _at(buf: npt.NDArray[np.uint8], pos: npt.NDArray[np.int64], dtype: str) -> npt.NDArray[Any]:
    """Values of ``dtype`` at byte positions ``pos`` of ``buf`` (callers check bounds)."""
    width = np.dtype(dtype).itemsize
    if pos.size == 0 or buf.shape[0] < width:
        return np.empty(pos.shape[0], dtype)
    win = np.lib.stride_tricks.sliding_window_view(buf, width)
    return np.ascontiguousarray(win[pos]).view(dtype).reshape(-1)


def _u64_at(buf: npt.NDArray[np.uint8], pos: npt.NDArray[np.int64]) -> npt.NDArray[np.uint64]:
    return _at(buf, pos, "<u8")


def _u16_at(buf: npt.NDArray[np.uint8], pos: npt.NDArray[np.int64]) -> npt.NDArray[np.uint16]:
    return _at(buf, pos, "<u2")


class McapSource(FileSource, SourceAccessors):
    """An MCAP file: ``ros1`` and ``cdr`` channels, read chunk by chunk.

    Opening reads the summary (or scans the file when it has none); nothing else.
    """

    format_name = "mcap"

    def __init__(self, path: str | Location) -> None:
        self.path = as_location(path)
        self._warnings: list[str] = []
        self._schemas: dict[int, _Schema] = {}
        self._channels: dict[int, _Channel] = {}
        self._blocks: list[_Block] = []
        self._counts: dict[int, int] = {}
        self._start: int | None = None
        self._end: int | None = None
        self._open_file()
        self._connections = self._make_connections()

    @property
    def message_indexed(self) -> bool:
        """Every block has Message Index records (a finalised file): channels are read
        through them, without walking the records of chunks that lack the channel."""
        return all(b.msg_index for b in self._blocks)

    # -- MessageSource -------------------------------------------------------------------

    def raw_batches(self, connection_ids: Collection[int]) -> Iterator[RawBatch]:
        """Messages of the given channels, one batch per chunk and channel, chunks in
        log-time order, messages sorted (stably) by log time within each batch."""
        wanted = {int(c) for c in connection_ids} & set(self._connections)
        if not wanted:
            return
        for block in self._blocks:
            if block.counts and not any(block.counts.get(c, 0) for c in wanted):
                continue
            if block.msg_index and not any(c in block.msg_index for c in wanted):
                continue
            yield from self._block_batches(block, wanted)

    # -- opening ---------------------------------------------------------------------------

    def _read_at(self, offset: int, length: int) -> bytes:
        self._file.seek(offset)
        return self._file.read(length)

    def _open(self) -> None:
        if self._size == 0:
            raise FormatError("empty file (0 bytes), not an MCAP file", self.path)
        head = self._read_at(0, len(MCAP_MAGIC) + _RECORD_HEAD)
        if not head.startswith(MCAP_MAGIC[:5]):
            raise FormatError("not an MCAP file (bad magic bytes)", self.path)
        if not head.startswith(MCAP_MAGIC):
            raise FormatError(f"unsupported MCAP version {head[5:6]!r}", self.path)
        if len(head) < len(MCAP_MAGIC) + _RECORD_HEAD:
            raise FormatError("truncated within the MCAP header record", self.path)
        header_end = len(MCAP_MAGIC) + _RECORD_HEAD + _length(head, len(MCAP_MAGIC))
        if header_end > self._size and self._resync(len(MCAP_MAGIC) + 1) is None:
            raise FormatError("truncated within the MCAP header record", self.path)
        if head[len(MCAP_MAGIC)] != OP_HEADER or header_end > self._size:
            # The records after it may be intact: the summary, or else the scan's resync.
            self._warn("corrupt MCAP header record (its bytes are lost)")
        if not self._read_summary():
            if self._read_at(self._size - len(MCAP_MAGIC), len(MCAP_MAGIC)) != MCAP_MAGIC:
                self._warn("no end magic (file truncated or not closed): read by linear scan")
            self._scan()
        self._blocks.sort(key=lambda b: (b.start_ns, b.record_offset))

    def _read_summary(self) -> bool:
        """Use the summary section when the file is complete and indexed; False if not."""
        if self._size < len(MCAP_MAGIC) * 2 + _FOOTER_LEN:
            return False
        tail = self._read_at(self._size - len(MCAP_MAGIC) - _FOOTER_LEN, _FOOTER_LEN + len(MCAP_MAGIC))
        if tail[-len(MCAP_MAGIC) :] != MCAP_MAGIC or tail[0] != OP_FOOTER:
            return False
        summary_start, _summary_offset = struct.unpack_from("<QQ", tail, _RECORD_HEAD)
        footer_at = self._size - len(MCAP_MAGIC) - _FOOTER_LEN
        if summary_start == 0 or not len(MCAP_MAGIC) <= summary_start <= footer_at:
            return False
        data = self._read_at(summary_start, footer_at - summary_start)
        chunk_indexes: list[_Block] = []
        stats: tuple[int, int, int, dict[int, int]] | None = None
        records, stop = _walk(data, 0, len(data))
        if stop != len(data):
            return False  # damaged: a record runs past the footer (then the file is scanned)
        try:
            for pos in records.tolist():
                op = data[pos]
                c = _Cursor(data, pos + _RECORD_HEAD, pos + _RECORD_HEAD + _length(data, pos))
                if op == OP_SCHEMA:
                    schema = _parse_schema(c)
                    if schema is not None:
                        self._schemas[schema.id] = schema
                elif op == OP_CHANNEL:
                    channel = _parse_channel(c)
                    self._channels[channel.id] = channel
                elif op == OP_CHUNK_INDEX:
                    chunk_indexes.append(self._parse_chunk_index(c))
                elif op == OP_STATISTICS:
                    count = c.u64()
                    c.raw(2 + 4 * 4)  # schema u16; channel, attachment, metadata, chunk u32 counts
                    t0, t1 = c.u64(), c.u64()
                    stats = (count, t0, t1, c.u16_u64_map())
        except _Short:
            self._schemas.clear()
            self._channels.clear()
            return False
        if stats is not None and stats[0] == 0:
            return True  # a finalised file without messages
        if not chunk_indexes or not all(b.msg_index for b in chunk_indexes):
            # No chunk or message indexes (unchunked writer): messages need a scan.
            return False
        for b in chunk_indexes:
            if not all(cid in self._channels for cid in b.msg_index):
                return False
        self._blocks = chunk_indexes
        if stats is not None:
            self._counts = dict(stats[3])
            self._start, self._end = stats[1], stats[2]
        else:
            self._count_from_message_indexes()
            self._start = min(b.start_ns for b in chunk_indexes)
            self._end = max(b.end_ns for b in chunk_indexes)
        return True

    def _parse_chunk_index(self, c: _Cursor) -> _Block:
        t0, t1 = c.u64(), c.u64()
        chunk_at, chunk_len = c.u64(), c.u64()
        offsets = c.u16_u64_map()
        index_len = c.u64()
        if chunk_at + chunk_len + index_len > self._size:
            raise _Short
        return _Block(
            t0,
            t1,
            chunk_at,
            chunk_len,
            True,
            msg_index=offsets,
            index_region=(chunk_at + chunk_len, index_len),
        )

    def _count_from_message_indexes(self) -> None:
        for block in self._blocks:
            region = self._read_at(*block.index_region)
            for cid, at in block.msg_index.items():
                n = _index_entries(region, at - block.index_region[0]).shape[0]
                block.counts[cid] = n
                self._counts[cid] = self._counts.get(cid, 0) + n

    def _scan(self) -> None:
        """Linear scan of the data section: schemas, channels, chunks, loose messages."""
        f = self._file
        pos = len(MCAP_MAGIC)
        loose: _Block | None = None
        counts: dict[int, int] = {}
        times: list[int] = []
        summary = False
        while True:
            head = self._read_at(pos, _RECORD_HEAD)
            if len(head) < _RECORD_HEAD:
                lost = self._size - pos
                if lost:
                    self._bytes_lost += lost
                    self._warn(f"truncated: {lost} bytes at the end are not a whole record")
                break
            op = head[0]
            (length,) = struct.unpack_from("<Q", head, 1)
            end = pos + _RECORD_HEAD + length
            problem = self._framing_problem(op, length, pos)
            if problem is not None and not summary:
                nxt = self._resync(pos + 1)
                if nxt is not None:
                    self._lose(nxt - pos, f"bytes {pos}-{nxt} are not a record (opcode"
                                          f" 0x{op:02x}: {problem}): {nxt - pos} bytes"
                                          " skipped to the next record")
                    pos = nxt
                    continue
            if end > self._size:
                self._bytes_lost += self._size - pos
                self._warn(
                    f"truncated: record at byte {pos} (opcode 0x{op:02x}) needs {length} bytes,"
                    f" file ends first; {self._size - pos} bytes lost"
                )
                break
            if problem is not None and not summary:
                self._lose(self._size - pos, f"record at byte {pos} (opcode 0x{op:02x}):"
                                             f" {problem}; {self._size - pos} bytes at the end"
                                             " lost")
                break
            if op == OP_FOOTER:
                if end + len(MCAP_MAGIC) < self._size:
                    tail = self._size - end - len(MCAP_MAGIC)
                    self._lose(tail, f"{tail} bytes after the footer at byte {pos} are not a"
                                     " record (lost)")
                break
            if op == OP_DATA_END:
                summary = True  # then only framed up to the footer (trailing bytes)
            if summary or (op == OP_HEADER and pos > len(MCAP_MAGIC)):
                if op == OP_HEADER:
                    break
                if op in (OP_SCHEMA, OP_CHANNEL) and length <= _MAX_CHUNK_RECORD:
                    # The summary repeats them: what a lost chunk held is found here.
                    with contextlib.suppress(_Short):
                        self._scan_record(op, f.read(length), 0, length, counts, [])
                pos = end
                continue
            if op == OP_CHUNK:
                loose = None
                content = f.read(length)
                block = self._scan_chunk(pos, content, counts)
                if block is not None:
                    self._blocks.append(block)
                    times += [block.start_ns, block.end_ns]
            elif op in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE):
                # A message's head is all the scan needs (its data is read when mapping).
                content = f.read(min(length, _MESSAGE_HEAD) if op == OP_MESSAGE else length)
                try:
                    self._scan_record(op, content, 0, len(content), counts, times)
                except _Short:
                    self._warn(f"corrupt record at byte {pos} (opcode 0x{op:02x}) skipped")
                    pos = end
                    continue
                if op == OP_MESSAGE:
                    if loose is None or end - loose.record_offset > _LOOSE_BLOCK_BYTES:
                        loose = _Block(times[-1], times[-1], pos, 0, False)
                        self._blocks.append(loose)
                    loose.record_length = end - loose.record_offset
                    loose.start_ns = min(loose.start_ns, times[-1])
                    loose.end_ns = max(loose.end_ns, times[-1])
            pos = end
        self._counts = counts
        if times:
            self._start, self._end = min(times), max(times)

    def _framing_problem(self, op: int, length: int, pos: int) -> str | None:
        """Why the record head at ``pos`` cannot be a record of the data section (damaged
        framing), or None."""
        if op == 0 or _LAST_OPCODE < op < _APPLICATION_OPCODES:
            return "not an opcode"
        if pos + _RECORD_HEAD + length > self._size:
            return f"needs {length} bytes, the file ends first"
        if op in (OP_CHUNK, OP_SCHEMA, OP_CHANNEL) and length > _MAX_CHUNK_RECORD:
            return f"an implausible length of {length} bytes"
        if op == OP_MESSAGE and length < _MESSAGE_HEAD:
            return f"a message record of {length} bytes"
        return None

    def _resync(self, start: int) -> int | None:
        """Where the next plausible data-section record starts at or after ``start``
        (:mod:`formats.ros.resync`), None when there is none."""
        return next_record(self._read_at, start, self._size, mcap_candidates(_RESYNC_OPS),
                           self._plausible)

    def _plausible(self, pos: int) -> bool:
        """Whether a record of the data section starts at ``pos``: a chunk that inflates
        and matches its CRC, a schema or channel that parses to its exact length, a message
        of a known channel or a message index followed by another record, a data end."""
        head = self._read_at(pos, _RECORD_HEAD)
        if len(head) < _RECORD_HEAD:
            return False
        op, length = head[0], _length(head, 0)
        if self._framing_problem(op, length, pos) is not None:
            return False
        end = pos + _RECORD_HEAD + length
        if op == OP_DATA_END:
            return length == 4
        if op == OP_MESSAGE:
            channel = struct.unpack("<H", self._read_at(pos + _RECORD_HEAD, 2))[0]
            return channel in self._channels and self._record_head_at(end)
        if op == OP_MESSAGE_INDEX:
            body = self._read_at(pos + _RECORD_HEAD, 6)
            n = struct.unpack_from("<I", body, 2)[0] if len(body) == 6 else -1
            return n % 16 == 0 and length == 6 + n and self._record_head_at(end)
        content = self._read_at(pos + _RECORD_HEAD, length)
        try:
            if op == OP_CHUNK:
                _inflated_chunk(content)
                return True
            c = _Cursor(content)
            if op == OP_SCHEMA:
                parsed = _parse_schema(c) is not None
            else:
                _parse_channel(c)
                parsed = True
            return parsed and c.pos == len(content)
        except (ChunkError, _Short):
            return False

    def _record_head_at(self, pos: int) -> bool:
        """Whether ``pos`` is the end of the file or a record head that fits in it."""
        if pos == self._size:
            return True
        head = self._read_at(pos, _RECORD_HEAD)
        if len(head) < _RECORD_HEAD:
            return False
        return 0 < head[0] <= _LAST_OPCODE and pos + _RECORD_HEAD + _length(head, 0) <= self._size

    def _scan_record(
        self,
        op: int,
        buf: bytes | memoryview,
        start: int,
        stop: int,
        counts: dict[int, int],
        times: list[int],
    ) -> None:
        c = _Cursor(buf, start, stop)
        if op == OP_SCHEMA:
            schema = _parse_schema(c)
            if schema is not None:
                self._schemas.setdefault(schema.id, schema)
        elif op == OP_CHANNEL:
            channel = _parse_channel(c)
            self._channels.setdefault(channel.id, channel)
        elif op == OP_MESSAGE:
            cid = c.u16()
            c.u32()
            times.append(c.u64())
            counts[cid] = counts.get(cid, 0) + 1

    def _scan_chunk(self, pos: int, content: bytes, counts: dict[int, int]) -> _Block | None:
        """Block of one chunk found by the scan (its records walked to count messages)."""
        try:
            buf = _inflated_chunk(content)
        except ChunkError as err:
            self._lose(_RECORD_HEAD + len(content), f"corrupt chunk at byte {pos} skipped ({err})")
            return None
        block = _Block(0, 0, pos, _RECORD_HEAD + len(content), True)
        rec, stop = _walk(buf, 0, len(buf))
        arr = np.frombuffer(buf, np.uint8)
        ops = arr[rec] if rec.size else np.empty(0, np.uint8)
        bad = 0
        # Schemas and channels: the first record of each id is parsed (Python), the rest of
        # a chunk's records only through numpy (a chunk may hold millions of them).
        for op in (OP_SCHEMA, OP_CHANNEL):
            at = rec[ops == op]
            if not at.size:
                continue
            ids = _u16_at(arr, at + _RECORD_HEAD) if at.size else at
            _, first = np.unique(ids, return_index=True)
            for a in at[np.sort(first)].tolist():
                try:
                    self._scan_record(op, buf, a + _RECORD_HEAD, a + _RECORD_HEAD + _length(buf, a),
                                      block.counts, [])
                except _Short:
                    bad += 1
        msgs = rec[ops == OP_MESSAGE]
        msgs = msgs[_u64_at(arr, msgs + 1) >= _MESSAGE_HEAD] if msgs.size else msgs
        if bad:
            self._warn(f"chunk at byte {pos}: {bad} corrupt schema/channel records skipped")
        if stop != len(buf):
            self._lose(len(buf) - stop, f"chunk at byte {pos}: its last {len(buf) - stop}"
                       " bytes are not a whole record (lost)")
        if msgs.size:
            cids = _u16_at(arr, msgs + _RECORD_HEAD)
            times = _u64_at(arr, msgs + _RECORD_HEAD + 6).astype(np.int64)
            ids, n = np.unique(cids, return_counts=True)
            for cid, k in zip(ids.tolist(), n.tolist(), strict=True):
                block.counts[cid] = k
                counts[cid] = counts.get(cid, 0) + k
            block.start_ns, block.end_ns = int(times.min()), int(times.max())
        return block

    def _make_connections(self) -> dict[int, Connection]:
        out: dict[int, Connection] = {}
        for cid in sorted(self._channels):
            ch = self._channels[cid]
            schema = self._schemas.get(ch.schema_id)
            out[cid] = Connection(
                id=cid,
                topic=ch.topic,
                msgtype=normalize_msgtype(schema.name) if schema else "",
                encoding=encoding_of(ch.message_encoding),
                msgdef=schema.data if schema else "",
                msgdef_format=schema.encoding if schema else "",
                count=int(self._counts.get(cid, 0)),
                md5sum=ch.metadata.get("md5sum", ""),
            )
        return out

    def _warn(self, line: str) -> None:
        if line not in self._warnings:
            self._warnings.append(line)

    def _lose(self, nbytes: int, line: str) -> None:
        """Record a loss of ``nbytes`` of the file, once (every pass meets it again)."""
        if line not in self._warnings:
            self._bytes_lost += nbytes
            self._warnings.append(line)

    # -- reading ---------------------------------------------------------------------------

    def _block_batches(self, block: _Block, wanted: set[int]) -> Iterator[RawBatch]:
        content = self._read_at(block.record_offset, block.record_length)
        if len(content) < block.record_length:
            line = f"chunk at byte {block.record_offset} is cut off by the end of file"
            if line not in self._warnings:  # each pass meets it again: count it once
                self._bytes_lost += len(content)
            self._warn(line)
            return
        if block.is_chunk:
            try:
                if not content or content[0] != OP_CHUNK:
                    raise ChunkError("chunk index points at a non-chunk record")
                data = _inflated_chunk(content[_RECORD_HEAD:])
            except ChunkError as err:
                lost = sum(block.counts.values())
                what = f"{lost} messages" if lost else "its messages"
                line = (f"corrupt chunk at byte {block.record_offset} skipped ({err});"
                        f" {what} lost")
                if line not in self._warnings:
                    self._messages_lost += lost
                self._lose(block.record_length, line)
                return
        else:
            data = content
        buf = np.frombuffer(data, dtype=np.uint8)
        if block.msg_index:
            found = self._indexed_messages(block, buf, wanted)
        else:
            found = self._walked_messages(block, data, wanted)
        for cid in sorted(found):
            rec = found[cid]
            log_time = _u64_at(buf, rec + _RECORD_HEAD + 6).astype(np.int64)
            # File order first (ties keep it), then log time: stable. Writers log in
            # time order almost always, so check before sorting.
            if np.any(log_time[1:] < log_time[:-1]):
                order = np.argsort(log_time, kind="stable")
                rec, log_time = rec[order], log_time[order]
            yield RawBatch(
                connection=self._connections[cid],
                log_time_ns=log_time,
                buffer=buf,
                offsets=rec + _RECORD_HEAD + _MESSAGE_HEAD,
                lengths=_u64_at(buf, rec + 1).astype(np.int64) - _MESSAGE_HEAD,
            )

    def _indexed_messages(
        self, block: _Block, buf: npt.NDArray[np.uint8], wanted: set[int]
    ) -> dict[int, npt.NDArray[np.int64]]:
        """Record offsets per channel from the Message Index records, validated."""
        region = self._read_at(*block.index_region)
        out: dict[int, npt.NDArray[np.int64]] = {}
        unindexed: set[int] = set()
        for cid in sorted(wanted & set(block.msg_index)):
            try:
                entries = _index_entries(region, block.msg_index[cid] - block.index_region[0])
            except _Short:
                unindexed.add(cid)
                continue
            rec = entries[:, 1].astype(np.int64)
            if np.any(rec[1:] < rec[:-1]):
                rec = np.sort(rec)
            if rec.size == 0:
                continue
            size = buf.shape[0]
            # Compared without adding to rec: a corrupt offset near 2**63 would overflow.
            ok = (rec >= 0) & (rec <= size - _RECORD_HEAD - _MESSAGE_HEAD)
            if ok.all():
                length = _u64_at(buf, rec + 1)
                ok = (
                    (buf[rec] == OP_MESSAGE)
                    & (length >= _MESSAGE_HEAD)
                    & (length <= size - rec - _RECORD_HEAD)
                )
                ok &= _u16_at(buf, rec + _RECORD_HEAD) == cid
            if not ok.all():
                unindexed.add(cid)
                continue
            out[cid] = rec
        if unindexed:
            # A damaged index, intact records: the chunk is walked for those channels.
            self._warn(f"chunk at byte {block.record_offset}: message index of channels"
                       f" {sorted(unindexed)} does not match its records; records walked")
            out |= self._walked_messages(block, buf, unindexed)
        return out

    def _walked_messages(
        self, block: _Block, data: bytes | memoryview | npt.NDArray[np.uint8], wanted: set[int]
    ) -> dict[int, npt.NDArray[np.int64]]:
        buf = np.frombuffer(data, dtype=np.uint8)
        rec, stop = _walk(buf, 0, buf.shape[0])
        if stop != buf.shape[0] and block.is_chunk:
            self._lose(buf.shape[0] - stop, f"chunk at byte {block.record_offset}: its last"
                       f" {buf.shape[0] - stop} bytes are not a whole record (lost)")
        if not rec.size:
            return {}
        rec = rec[buf[rec] == OP_MESSAGE]
        rec = rec[_u64_at(buf, rec + 1) >= _MESSAGE_HEAD]
        cids = _u16_at(buf, rec + _RECORD_HEAD)
        return {c: rec[cids == c] for c in sorted(wanted) if np.any(cids == c)}


def _length(buf: bytes | memoryview, pos: int) -> int:
    return int(struct.unpack_from("<Q", buf, pos + 1)[0])


def _chunk_records(content: bytes | memoryview) -> tuple[memoryview, str, int, int]:
    """(compressed records, compression, uncompressed size, crc) of a Chunk record's content."""
    c = _Cursor(content)
    try:
        c.u64()
        c.u64()
        size = c.u64()
        crc = c.u32()
        compression = c.string()
        n = c.u64()
        start = c._take(n)
    except _Short:
        raise ValueError("chunk record is cut short") from None
    return memoryview(content)[start : start + n], compression, size, crc


def _inflated_chunk(content: bytes | memoryview) -> bytes | memoryview:
    """The records of a Chunk record's content, inflated within the bound of
    :mod:`formats.ros.inflate` and checked against the chunk's CRC. Raises ChunkError."""
    try:
        records, compression, size, crc = _chunk_records(content)
    except ValueError as err:
        raise ChunkError(str(err)) from err
    data = inflate(compression, records, size)
    if crc and zlib.crc32(data) != crc:
        raise ChunkError("CRC mismatch")
    return data


def _index_entries(region: bytes, at: int) -> npt.NDArray[np.uint64]:
    """(log_time, offset) rows of the Message Index record at ``region[at:]``."""
    if at < 0 or at + _RECORD_HEAD + 6 > len(region) or region[at] != OP_MESSAGE_INDEX:
        raise _Short
    n = struct.unpack_from("<I", region, at + _RECORD_HEAD + 2)[0]
    start = at + _RECORD_HEAD + 6
    if n % 16 or start + n > len(region) or n + 6 > _length(region, at):
        raise _Short
    return np.frombuffer(region, dtype="<u8", count=n // 8, offset=start).reshape(-1, 2)


def _reason(err: BaseException) -> str:
    text = str(err) or type(err).__name__
    return " ".join(text.split())
