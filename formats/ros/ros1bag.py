"""ROS 1 bags (rosbag format v2.0) as a :class:`~formats.ros.source.MessageSource`.

Our own parser rather than rosbags' reader: a :class:`RawBatch` is one decompressed chunk
buffer plus per-message offsets/lengths (zero-copy), which the numpy decoders need.

Format (http://wiki.ros.org/Bags/Format/2.0): ``#ROSBAG V2.0\\n``, then records
``<header_len u32><header: (field_len u32, name=value)*><data_len u32><data>``. The bag
header record (op 0x03) holds ``index_pos``; chunks (op 0x05, compression none/bz2/lz4
— lz4 is the LZ4 *frame* format roslz4 writes) contain connection (0x07) and message
(0x02) records and are each followed by index data records (0x04: time + offset of each
message in the uncompressed chunk); at ``index_pos`` come the connection records and one
chunk info record (0x06) per chunk.

A bag whose index is missing (recording killed before ``rosbag reindex``) or cut off is
read by scanning the intact records, with one line in :attr:`Ros1BagSource.warnings`.
"""

from __future__ import annotations

import struct
from collections.abc import Collection, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from formats.errors import FormatError
from formats.magic import ROS1_MAGIC
from formats.options import ReaderOptions, ReaderSettings
from formats.ros.inflate import MAX_CHUNK_BYTES, ChunkError, inflate, inflate_prefix
from formats.ros.resync import ROS1_MAX_HEADER, next_record, ros1_candidates
from formats.ros.source import Connection, FileSource, RawBatch, normalize_msgtype
from formats.storage.location import Location, as_location

if TYPE_CHECKING:
    from formats.ros.reader import RosLogReader


OP_MSGDATA = 0x02
OP_BAGHEADER = 0x03
OP_IDXDATA = 0x04
OP_CHUNK = 0x05
OP_CHUNKINFO = 0x06
OP_CONNECTION = 0x07

_U32 = struct.Struct("<I")
_INDEX_DTYPE = np.dtype([("sec", "<u4"), ("nsec", "<u4"), ("offset", "<u4")])
_COUNT_DTYPE = np.dtype([("conn", "<u4"), ("count", "<u4")])
# A record header longer than this is garbage, not a header (the biggest real ones are
# connection headers with message definitions, which live in the record *data*).
_MAX_HEADER = 1 << 20


class _Corrupt(Exception):
    """A record does not parse (internal; turned into FormatError or a warning)."""


@dataclass
class _Chunk:
    """One chunk: where it is, its time span and per-connection message counts.

    ``index`` is filled when the bag was scanned (no usable index): per connection the
    log times (ns) and record offsets in the uncompressed chunk. ``partial`` marks a
    chunk cut off by the end of the file, of which only the intact records are used.
    """

    pos: int
    start_ns: int
    end_ns: int
    counts: dict[int, int]
    index: dict[int, tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]] | None = None
    partial: bool = False
    length: int = 0  # bytes from ``pos`` to the next chunk (or the index): lost with it


@dataclass
class _ConnRecord:
    id: int
    topic: str
    fields: dict[str, bytes]
    count: int = 0


@dataclass
class _ScanResult:
    conns: dict[int, _ConnRecord] = field(default_factory=dict)
    chunks: list[_Chunk] = field(default_factory=list)
    end: int = 0  # end of the last intact record
    salvaged: int = 0  # messages recovered from a chunk cut off by the end of the file
    lost: int = 0  # bytes of corrupt records skipped before ``end``
    lines: list[str] = field(default_factory=list)  # one per corrupt record skipped


def parse_header(data: bytes | memoryview) -> dict[str, bytes]:
    """Fields of a record header (``name=value`` entries, each prefixed by its u32 length)."""
    mv = memoryview(data)
    fields: dict[str, bytes] = {}
    pos, end = 0, len(mv)
    while pos < end:
        if pos + 4 > end:
            raise _Corrupt("header field length cut off")
        (n,) = _U32.unpack_from(mv, pos)
        pos += 4
        if n > end - pos:
            raise _Corrupt(f"header field of {n} bytes overruns the header")
        entry = bytes(mv[pos : pos + n])
        pos += n
        eq = entry.find(b"=")
        if eq <= 0:
            raise _Corrupt("header field without 'name='")
        try:
            name = entry[:eq].decode("ascii")
        except UnicodeDecodeError as err:
            raise _Corrupt("header field name is not ASCII") from err
        fields[name] = entry[eq + 1 :]
    return fields


def _u32(fields: dict[str, bytes], name: str) -> int:
    v = fields.get(name)
    if v is None or len(v) != 4:
        raise _Corrupt(f"header field '{name}' missing or not 4 bytes")
    return int(_U32.unpack(v)[0])


def _u64(fields: dict[str, bytes], name: str) -> int:
    v = fields.get(name)
    if v is None or len(v) != 8:
        raise _Corrupt(f"header field '{name}' missing or not 8 bytes")
    return int(struct.unpack("<Q", v)[0])


def _time(fields: dict[str, bytes], name: str) -> int:
    """A ROS time field (u32 sec, u32 nsec) in ns."""
    v = fields.get(name)
    if v is None or len(v) != 8:
        raise _Corrupt(f"header field '{name}' missing or not 8 bytes")
    sec, nsec = struct.unpack("<II", v)
    return int(sec) * 1_000_000_000 + int(nsec)


def _op(fields: dict[str, bytes]) -> int:
    v = fields.get("op")
    if v is None or len(v) != 1:
        raise _Corrupt("record without a one-byte 'op' field")
    return v[0]


def _decompress(compression: str, data: bytes, size: int, partial: bool) -> bytes:
    """Uncompressed chunk data within the bound of :mod:`formats.ros.inflate`; ``partial``
    accepts a cut-off stream (returns what decodes)."""
    try:
        if partial:
            return inflate_prefix(compression, data, size)
        return bytes(inflate(compression, data, size))
    except ChunkError as err:
        raise _Corrupt(str(err)) from err


def _conn_record(header: dict[str, bytes], data: bytes) -> _ConnRecord:
    cid = _u32(header, "conn")
    topic = header.get("topic", b"").decode("utf-8", "replace")
    fields = parse_header(data)
    if "type" not in fields:
        raise _Corrupt(f"connection {cid} has no 'type'")
    return _ConnRecord(cid, topic, fields)


class Ros1BagSource(FileSource):
    """A ROS 1 bag file: connections from the index, raw messages chunk by chunk.

    Opening reads the bag header and the index at its end (connections and chunk infos);
    messages are read by :meth:`raw_batches`, one decompressed chunk at a time.
    Raises :class:`FormatError` naming the file for a 0-byte file, a file that is not a
    bag, or a corrupt bag header.
    """

    format_name = "ros1"

    def __init__(self, path: str | Location) -> None:
        self.path = as_location(path)
        self._warnings: list[str] = []
        self._bytes_lost = 0
        self._messages_lost = 0
        self._open_file()

    # ------------------------------------------------------------------ opening

    def _open(self) -> None:
        if self._size == 0:
            raise FormatError("empty file (0 bytes), not a ROS 1 bag", self.path)
        head = self._read_at(0, len(ROS1_MAGIC))
        if head != ROS1_MAGIC:
            if head.startswith(b"#ROSBAG V"):
                version = head[9:].split(b"\n")[0].decode("ascii", "replace")
                raise FormatError(
                    f"rosbag format version {version} is not supported (only 2.0)", self.path
                )
            raise FormatError("not a ROS 1 bag (no '#ROSBAG V2.0' magic line)", self.path)
        reason = ""
        try:
            header, _data, end = self._record_at(len(ROS1_MAGIC))
            if _op(header) != OP_BAGHEADER:
                raise _Corrupt("first record is not the bag header")
            index_pos = _u64(header, "index_pos")
            conn_count = _u32(header, "conn_count")
            chunk_count = _u32(header, "chunk_count")
        except _Corrupt as err:
            # Its records may be intact: read them by scanning from the first one found.
            first = self._resync(len(ROS1_MAGIC) + 1)
            if first is None:
                raise FormatError(f"corrupt bag header ({err})", self.path) from err
            reason = f"corrupt bag header ({err}; {first - len(ROS1_MAGIC)} bytes lost)"
            self._bytes_lost += first - len(ROS1_MAGIC)
            end, index_pos = first, 0
        self._data_start = end

        if reason:
            pass  # the bag header is lost: scan
        elif index_pos == 0:
            reason = "bag is not indexed (index_pos 0, recording not closed)"
        elif index_pos < end or index_pos > self._size:
            reason = f"index position {index_pos} is outside the file ({self._size} bytes)"
        else:
            try:
                conns, chunks, index_end = self._read_index(index_pos, conn_count, chunk_count)
            except _Corrupt as err:
                reason = f"index at byte {index_pos} is unreadable ({err})"
            else:
                if index_end < self._size:
                    tail = self._size - index_end
                    self._bytes_lost += tail
                    self._warnings.append(f"{self.path}: {tail} bytes after the index at byte"
                                          f" {index_end} are not a record (lost)")
        if reason:
            scan = self._scan()
            conns, chunks = scan.conns, scan.chunks
            lost = self._size - scan.end
            self._bytes_lost += lost + scan.lost
            n = sum(c.count for c in conns.values())
            cut = f" ({scan.salvaged} of them from a cut-off chunk)" if scan.salvaged else ""
            self._warnings.append(
                f"{self.path}: {reason}: read by scanning, {n} messages recovered{cut}, "
                f"{lost} bytes at the end lost"
            )
            self._warnings += [f"{self.path}: {line}" for line in scan.lines]
        data_end = index_pos if not reason else self._size
        by_pos = sorted(chunks, key=lambda c: c.pos)
        for a, b in zip(by_pos, [c.pos for c in by_pos[1:]] + [data_end], strict=False):
            a.length = max(0, b - a.pos)
        self._lost_chunks: set[int] = set()
        self._chunks = sorted(chunks, key=lambda c: (c.start_ns, c.pos))
        self._connections = [
            Connection(
                id=c.id,
                topic=c.topic,
                msgtype=normalize_msgtype(c.fields["type"].decode("utf-8", "replace")),
                encoding="ros1",
                msgdef=c.fields.get("message_definition", b"").decode("utf-8", "replace"),
                msgdef_format="ros1msg",
                count=c.count,
                md5sum=c.fields.get("md5sum", b"").decode("ascii", "replace"),
            )
            for c in sorted(conns.values(), key=lambda c: c.id)
        ]
        self._by_id = {c.id: c for c in self._connections}

    def _read_at(self, pos: int, n: int) -> bytes:
        self._file.seek(pos)
        return self._file.read(n)

    def _header_at(
        self, pos: int, max_header: int = _MAX_HEADER
    ) -> tuple[dict[str, bytes], int, int]:
        """Header fields, data length and end of the record at ``pos`` (the file is left at
        its data); the whole record must lie within the file."""
        raw = self._read_at(pos, 4)
        if len(raw) < 4:
            raise _Corrupt(f"record at byte {pos} cut off")
        (hlen,) = _U32.unpack(raw)
        if hlen > max_header:
            raise _Corrupt(f"record at byte {pos} has an implausible header length {hlen}")
        if pos + 8 + hlen > self._size:
            raise _Corrupt(f"record at byte {pos} cut off")
        hdr = self._file.read(hlen + 4)
        if len(hdr) < hlen + 4:
            raise _Corrupt(f"record at byte {pos} cut off")
        header = parse_header(hdr[:hlen])
        (dlen,) = _U32.unpack_from(hdr, hlen)
        # Checked before reading: read(n) allocates n bytes up front, and a corrupt length
        # may declare up to 4 GiB in a file of a few KiB.
        if pos + 8 + hlen + dlen > self._size:
            raise _Corrupt(f"record at byte {pos} cut off")
        return header, dlen, pos + 8 + hlen + dlen

    def _record_at(self, pos: int) -> tuple[dict[str, bytes], bytes, int]:
        """Header fields, data and end position of the record at ``pos`` in the file."""
        header, dlen, end = self._header_at(pos)
        data = self._file.read(dlen)
        if len(data) < dlen:
            raise _Corrupt(f"record at byte {pos} cut off")
        return header, data, end

    def _resync(self, start: int) -> int | None:
        """Where the next plausible record starts at or after ``start`` (damaged framing
        skipped: :mod:`formats.ros.resync`), None when there is none."""
        return next_record(self._read_at, start, self._size, ros1_candidates, self._plausible)

    def _plausible(self, pos: int) -> bool:
        """Whether a chunk, connection, index data or chunk info record starts at ``pos``:
        its header parses and holds the fields its op needs, sizes agreeing."""
        try:
            header, dlen, _end = self._header_at(pos, ROS1_MAX_HEADER)
            op = _op(header)
            if op == OP_CHUNK:
                compression = header.get("compression", b"").decode("ascii", "replace")
                size = _u32(header, "size")
                return compression in ("none", "bz2", "lz4") and size <= MAX_CHUNK_BYTES and (
                    compression != "none" or size == dlen)
            if op == OP_CONNECTION:
                _u32(header, "conn")
                return "topic" in header
            if op == OP_IDXDATA:
                _u32(header, "conn")
                return _u32(header, "ver") == 1 and dlen == 12 * _u32(header, "count")
            if op == OP_CHUNKINFO:
                _u64(header, "chunk_pos")
                _time(header, "start_time")
                _time(header, "end_time")
                return _u32(header, "ver") == 1 and dlen == 8 * _u32(header, "count")
        except _Corrupt:
            return False
        return False  # a message outside a chunk, a second bag header: not resynced to

    def _read_index(
        self, index_pos: int, conn_count: int, chunk_count: int
    ) -> tuple[dict[int, _ConnRecord], list[_Chunk], int]:
        """Connections and chunk infos of the index at ``index_pos``, and where it ends."""
        conns: dict[int, _ConnRecord] = {}
        chunks: list[_Chunk] = []
        pos = index_pos
        while len(conns) < conn_count or len(chunks) < chunk_count:
            header, data, pos = self._record_at(pos)
            op = _op(header)
            if op == OP_CONNECTION:
                rec = _conn_record(header, data)
                conns[rec.id] = rec
            elif op == OP_CHUNKINFO:
                if _u32(header, "ver") != 1:
                    raise _Corrupt("unsupported chunk info version")
                n = _u32(header, "count")
                if len(data) != 8 * n:
                    raise _Corrupt("chunk info data has the wrong length")
                arr = np.frombuffer(data, _COUNT_DTYPE)
                counts = {int(c): int(k) for c, k in zip(arr["conn"], arr["count"], strict=True)}
                chunk_pos = _u64(header, "chunk_pos")
                if not self._data_start <= chunk_pos < index_pos:
                    raise _Corrupt(f"chunk position {chunk_pos} outside the data section")
                chunks.append(
                    _Chunk(
                        chunk_pos, _time(header, "start_time"), _time(header, "end_time"), counts
                    )
                )
            else:
                raise _Corrupt(f"unexpected record op {op:#x} in the index")
        for ch in chunks:
            for cid, k in ch.counts.items():
                if cid not in conns:
                    raise _Corrupt(f"chunk info names unknown connection {cid}")
                conns[cid].count += k
        return conns, chunks, pos

    def _scan(self) -> _ScanResult:
        """Walk the records from the start, keeping every intact one (no index needed)."""
        res = _ScanResult(end=self._data_start)
        pos = self._data_start
        while pos < self._size:
            try:
                header, data, end = self._record_at(pos)
                op = _op(header)
            except _Corrupt as err:
                # A chunk whose header is intact and whose data is cut off (by the end of
                # the file, or by a damaged length) gives its intact start; the walk goes
                # on after what it gave, or after the damage.
                salvaged, resume = self._scan_partial_chunk(pos, res)
                res.salvaged += salvaged
                nxt = self._resync(resume)
                if nxt is None:  # nothing intact after it: the tail
                    break
                res.lost += nxt - resume if salvaged else nxt - pos
                res.lines.append(f"bytes {pos}-{nxt} are not a record ({err}): {nxt - pos}"
                                 " bytes skipped to the next record"
                                 + (f" ({salvaged} messages recovered)" if salvaged else ""))
                pos = nxt
                continue
            if op == OP_CHUNK:
                try:
                    raw = _decompress(
                        header.get("compression", b"").decode("ascii", "replace"),
                        data,
                        _u32(header, "size"),
                        partial=False,
                    )
                except _Corrupt as err:
                    # Its framing is intact: the chunk (and its index records) is lost,
                    # the records after it are read.
                    res.lost += end - pos
                    res.lines.append(f"corrupt chunk at byte {pos} skipped ({err})")
                else:
                    self._index_chunk(pos, raw, res, partial=False)
            elif op == OP_CONNECTION:
                try:
                    rec = _conn_record(header, data)
                except _Corrupt as err:
                    res.lost += end - pos
                    res.lines.append(f"corrupt connection record at byte {pos} skipped ({err})")
                else:
                    res.conns.setdefault(rec.id, rec)
            pos = end
            res.end = end
        self._keep_known(res)
        return res

    def _scan_partial_chunk(self, pos: int, res: _ScanResult) -> tuple[int, int]:
        """Recover the intact messages of a chunk whose data is cut off; returns how many,
        and where to look for the next record (after an uncompressed chunk's recovered
        bytes, else the byte after ``pos``)."""
        found = self._partial_chunk(pos)
        if found is None:
            return 0, pos + 1
        data, data_start, compression = found
        n = self._index_chunk(pos, data, res, partial=True)
        return n, (data_start + len(data) if n and compression == "none" else pos + 1)

    def _partial_chunk_data(self, pos: int) -> bytes | None:
        found = self._partial_chunk(pos)
        return None if found is None else found[0]

    def _partial_chunk(self, pos: int) -> tuple[bytes, int, str] | None:
        """(what its data inflates to, where its data starts, compression) of a chunk
        record at ``pos`` whose header is intact, or None."""
        raw = self._read_at(pos, 4)
        if len(raw) < 4:
            return None
        (hlen,) = _U32.unpack(raw)
        if hlen > _MAX_HEADER:
            return None
        hdr = self._file.read(hlen + 4)
        if len(hdr) < hlen + 4:
            return None
        try:
            header = parse_header(hdr[:hlen])
            if _op(header) != OP_CHUNK:
                return None
            compression = header.get("compression", b"").decode("ascii", "replace")
            size = _u32(header, "size")
            if size > MAX_CHUNK_BYTES:
                return None
            # At most what ``size`` bytes compress to (every codec stays within 1/8 more).
            data = self._file.read(size + (size >> 3) + (1 << 16))
            inflated = _decompress(compression, data, size, partial=True)
        except _Corrupt:
            return None
        return inflated, pos + 8 + hlen, compression

    def _index_chunk(self, pos: int, raw: bytes, res: _ScanResult, *, partial: bool) -> int:
        """Index the message records of an uncompressed chunk; returns messages found."""
        times: dict[int, list[int]] = {}
        offsets: dict[int, list[int]] = {}
        mv = memoryview(raw)
        off, n = 0, len(raw)
        # Python loop: only on the fallback path for bags without a usable index.
        while off + 4 <= n:
            (hlen,) = _U32.unpack_from(mv, off)
            if off + 8 + hlen > n:
                break
            try:
                header = parse_header(mv[off + 4 : off + 4 + hlen])
                op = _op(header)
            except _Corrupt:
                break
            (dlen,) = _U32.unpack_from(mv, off + 4 + hlen)
            end = off + 8 + hlen + dlen
            if end > n:
                break
            try:
                if op == OP_MSGDATA:
                    cid, t = _u32(header, "conn"), _time(header, "time")
                    times.setdefault(cid, []).append(t)
                    offsets.setdefault(cid, []).append(off)
                elif op == OP_CONNECTION:
                    rec = _conn_record(header, bytes(mv[off + 8 + hlen : end]))
                    res.conns.setdefault(rec.id, rec)
            except _Corrupt:
                break
            off = end
        if off < n and not partial:
            res.lost += n - off
            res.lines.append(f"chunk at byte {pos}: its last {n - off} bytes are not whole"
                             " records (lost)")
        # Every connection id is kept here: its connection record may come later (the
        # index section of a bag whose first chunk was lost); _keep_known filters.
        index = {
            cid: (np.asarray(t, np.int64), np.asarray(offsets[cid], np.int64))
            for cid, t in times.items()
        }
        if not index:
            return 0
        counts = {cid: int(t.shape[0]) for cid, (t, _o) in index.items()}
        start = min(int(t.min()) for t, _o in index.values())
        stop = max(int(t.max()) for t, _o in index.values())
        res.chunks.append(_Chunk(pos, start, stop, counts, index, partial))
        return sum(counts.values())

    def _keep_known(self, res: _ScanResult) -> None:
        """Keep the scanned chunks' messages of the connections found (anywhere in the
        file), count them; messages of connections whose records were lost are lost."""
        kept: list[_Chunk] = []
        unknown: dict[int, int] = {}
        for ch in res.chunks:
            assert ch.index is not None
            for cid, (t, _o) in ch.index.items():
                if cid not in res.conns:
                    unknown[cid] = unknown.get(cid, 0) + int(t.shape[0])
            ch.index = {c: v for c, v in ch.index.items() if c in res.conns}
            if not ch.index:
                continue
            ch.counts = {c: int(v[0].shape[0]) for c, v in ch.index.items()}
            ch.start_ns = min(int(t.min()) for t, _o in ch.index.values())
            ch.end_ns = max(int(t.max()) for t, _o in ch.index.values())
            for c, k in ch.counts.items():
                res.conns[c].count += k
            kept.append(ch)
        res.chunks = kept
        if unknown:
            n = sum(unknown.values())
            self._messages_lost += n
            res.lines.append(f"{n} messages of connections {sorted(unknown)} whose connection"
                             " records were lost")

    # ------------------------------------------------------------------ MessageSource

    @property
    def connections(self) -> list[Connection]:
        """Connections in id order (several may share a topic)."""
        return list(self._connections)

    @property
    def start_ns(self) -> int | None:
        """Log time of the first message (ns), None for a bag without messages."""
        return min((c.start_ns for c in self._chunks), default=None)

    @property
    def end_ns(self) -> int | None:
        """Log time of the last message (ns), None for a bag without messages."""
        return max((c.end_ns for c in self._chunks), default=None)

    @property
    def bytes_lost(self) -> int:
        """Bytes at the end of a bag cut by power loss that could not be read."""
        return self._bytes_lost

    @property
    def warnings(self) -> list[str]:
        """One line per loss found while reading (missing index, truncation)."""
        return list(self._warnings)

    @property
    def messages_lost(self) -> int:
        """Messages the index counts in chunks that were lost."""
        return self._messages_lost

    @property
    def chunk_count(self) -> int:
        """Number of (intact) chunks."""
        return len(self._chunks)

    def raw_batches(self, connection_ids: Collection[int]) -> Iterator[RawBatch]:
        """Messages of the given connections in log order: chunks by start time, within a
        chunk one batch per connection (id order), sorted by log time (stable).

        One decompressed chunk is held at a time — except where chunks overlap in time
        (bags merged by tools; ``rosbag record`` never writes such), which are merged
        into one buffer so their messages still come out in time order. A chunk the index
        points to that does not parse is skipped, its loss recorded (:attr:`warnings`,
        :attr:`bytes_lost`)."""
        wanted = sorted({int(c) for c in connection_ids} & self._by_id.keys())
        if not wanted:
            return
        chunks = [ch for ch in self._chunks if any(ch.counts.get(c, 0) for c in wanted)]
        group: list[_Chunk] = []
        group_end = 0
        for chunk in chunks:
            if group and chunk.start_ns >= group_end:
                yield from self._group_batches(group, wanted)
                group = []
            group_end = max(group_end, chunk.end_ns) if group else chunk.end_ns
            group.append(chunk)
        if group:
            yield from self._group_batches(group, wanted)

    def _group_batches(self, group: list[_Chunk], wanted: list[int]) -> Iterator[RawBatch]:
        """Batches of a run of chunks that overlap in time (usually just one chunk), merged
        into one buffer of at most MAX_CHUNK_BYTES beyond its first chunk (past that, the
        run is cut: messages then come in time order within each part). A chunk that does
        not parse is skipped and recorded as a loss."""
        bufs: list[npt.NDArray[np.uint8]] = []
        parts: dict[int, list[tuple[npt.NDArray[np.int64], ...]]] = {}
        base = 0
        for chunk in group:
            present = [c for c in wanted if chunk.counts.get(c, 0) > 0]
            try:
                buf, located = self._chunk_messages(chunk, present)
            except _Corrupt as err:
                self._lose(chunk, f"corrupt chunk at byte {chunk.pos} skipped ({err})")
                continue
            if bufs and base + buf.shape[0] > MAX_CHUNK_BYTES:
                yield from _merged(bufs, parts, self._by_id)
                bufs, parts, base = [], {}, 0
            for cid, (t, start, length) in located.items():
                parts.setdefault(cid, []).append((t, start + base, length))
            bufs.append(buf)
            base += buf.shape[0]
        if bufs:
            yield from _merged(bufs, parts, self._by_id)

    def _chunk_messages(
        self, chunk: _Chunk, present: list[int]
    ) -> tuple[npt.NDArray[np.uint8], dict[int, tuple[npt.NDArray[np.int64], ...]]]:
        """A chunk's buffer and, per connection, (log times, data offsets, lengths); a
        chunk whose index records do not match its records is walked instead."""
        buf, index = self._load_chunk(chunk, present)
        try:
            return buf, {cid: self._locate(buf, *index[cid]) for cid in present if cid in index}
        except _Corrupt as err:
            walked = self._walk_chunk(chunk, buf, present, f"its index does not match its"
                                      f" records ({err})")
            return buf, {cid: self._locate(buf, *walked[cid]) for cid in present
                         if cid in walked}

    def _walk_chunk(
        self, chunk: _Chunk, buf: npt.NDArray[np.uint8], present: list[int], why: str
    ) -> dict[int, tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]]:
        """(log times, record offsets) per connection found by walking a chunk's records,
        when its index records cannot be used (``why``, said once in :attr:`warnings`)."""
        res = _ScanResult(conns={c: _ConnRecord(c, "", {}) for c in present})
        self._index_chunk(chunk.pos, buf.tobytes(), res, partial=True)
        if not res.chunks or res.chunks[0].index is None:
            raise _Corrupt(f"{why}; no records found walking it")
        line = f"{self.path}: chunk at byte {chunk.pos}: {why}; records walked"
        if line not in self._warnings:  # every pass over the bag meets it again
            self._warnings.append(line)
        return res.chunks[0].index

    def _lose(self, chunk: _Chunk, line: str) -> None:
        """Record a chunk as lost, once (every pass over the bag meets it again)."""
        if chunk.pos in self._lost_chunks:
            return
        self._lost_chunks.add(chunk.pos)
        self._bytes_lost += chunk.length
        self._messages_lost += sum(chunk.counts.values())
        self._warnings.append(f"{self.path}: {line}")

    def _load_chunk(
        self, chunk: _Chunk, present: list[int]
    ) -> tuple[
        npt.NDArray[np.uint8], dict[int, tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]]
    ]:
        if chunk.partial:
            data = self._partial_chunk_data(chunk.pos)
            if data is None:  # pragma: no cover - it decoded while scanning
                raise _Corrupt("cut-off chunk no longer decodes")
            assert chunk.index is not None
            return np.frombuffer(data, np.uint8), chunk.index
        header, data, end = self._record_at(chunk.pos)
        if _op(header) != OP_CHUNK:
            raise _Corrupt("no chunk record at this position")
        compression = header.get("compression", b"").decode("ascii", "replace")
        raw = _decompress(compression, data, _u32(header, "size"), partial=False)
        buf = np.frombuffer(raw, np.uint8)
        if chunk.index is not None:
            return buf, chunk.index
        try:
            return buf, self._read_chunk_index(end, chunk, set(present))
        except _Corrupt as err:  # the chunk is intact, the index records after it are not
            return buf, self._walk_chunk(chunk, buf, present,
                                         f"its index records are unreadable ({err})")

    def _read_chunk_index(
        self, pos: int, chunk: _Chunk, present: set[int]
    ) -> dict[int, tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]]:
        """The index data records that follow a chunk: (log times ns, record offsets)."""
        index: dict[int, tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]] = {}
        for _ in range(len(chunk.counts)):
            header, data, pos = self._record_at(pos)
            if _op(header) != OP_IDXDATA:
                raise _Corrupt("index data record missing after the chunk")
            if _u32(header, "ver") != 1:
                raise _Corrupt("unsupported index data version")
            cid, count = _u32(header, "conn"), _u32(header, "count")
            if len(data) != 12 * count:
                raise _Corrupt("index data has the wrong length")
            if cid not in present:
                continue
            arr = np.frombuffer(data, _INDEX_DTYPE)
            t = arr["sec"].astype(np.int64) * 1_000_000_000 + arr["nsec"].astype(np.int64)
            index[cid] = (t, arr["offset"].astype(np.int64))
        return index

    @staticmethod
    def _locate(
        buf: npt.NDArray[np.uint8],
        times: npt.NDArray[np.int64],
        rec_offsets: npt.NDArray[np.int64],
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """(log times, data offsets, data lengths) of message records at ``rec_offsets``."""
        n = buf.shape[0]
        if rec_offsets.size and (rec_offsets.min() < 0 or rec_offsets.max() + 8 > n):
            raise _Corrupt(f"index offset outside the {n}-byte chunk")
        hlen = _gather_u32(buf, rec_offsets)
        dpos = rec_offsets + 4 + hlen
        if dpos.size and dpos.max() + 4 > n:
            raise _Corrupt("message record header overruns the chunk")
        dlen = _gather_u32(buf, dpos)
        start = dpos + 4
        if start.size and (start + dlen).max() > n:
            raise _Corrupt("message data overruns the chunk")
        return times, start, dlen


def _merged(
    bufs: list[npt.NDArray[np.uint8]],
    parts: dict[int, list[tuple[npt.NDArray[np.int64], ...]]],
    by_id: dict[int, Connection],
) -> list[RawBatch]:
    """One batch per connection over the buffers joined, each sorted by log time."""
    buffer = bufs[0] if len(bufs) == 1 else np.concatenate(bufs)
    out = []
    for cid in sorted(parts):
        t, start, length = (np.concatenate(col) for col in zip(*parts[cid], strict=True))
        if t.size > 1 and bool(np.any(np.diff(t) < 0)):
            order = np.argsort(t, kind="stable")
            t, start, length = t[order], start[order], length[order]
        out.append(RawBatch(by_id[cid], t, buffer, start, length))
    return out


def _gather_u32(buf: npt.NDArray[np.uint8], pos: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    """Little-endian u32 values at byte positions ``pos`` of ``buf`` (vectorised: a view
    of the buffer with a 1-byte stride, then one fancy-index copy)."""
    n = buf.shape[0] - 3
    if pos.size == 0 or n <= 0:
        return np.empty(0, np.int64)
    items = np.ndarray(shape=(n,), dtype="<u4", buffer=buf, strides=(1,))
    return items[pos].astype(np.int64)


def open_ros1_bag(path: str | Path, config: ReaderSettings | None = None) -> RosLogReader:
    """A :class:`~formats.ros.reader.RosLogReader` over a ROS 1 bag file."""
    from formats.ros.reader import RosLogReader

    source = Ros1BagSource(path)
    try:
        return RosLogReader(source, config if config is not None else ReaderOptions())
    except BaseException:
        source.close()
        raise
