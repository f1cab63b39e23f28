"""Several files of one recording as one :class:`~formats.ros.source.MessageSource`.

``rosbag record --split`` writes ``name_0.bag``, ``name_1.bag``, … one after the other;
many robots log sonar and odometry into separate bags that overlap in time. A
:class:`MultiSource` reads such files as one log, the way ``rosbags``' ``AnyReader``
accepts several paths: one connection list, one time span, one message stream in log
order. It is built by :func:`formats.open_log` (the one place a log is opened) over the
sources of the files, so every ROS format (ROS 1 bags, ROS 2 bags, MCAP) gets it and the
readers above (topic choice, tf chains, sensor ids) see one log.

Rules (each refusal is one :class:`FormatError` line naming the files):

* a topic has one message type in every file that has it; files that disagree are
  refused. The same topic in several files is read as one topic, merged by time (split
  bags; ``/tf`` recorded into every bag);
* the files form one recording in time: sorted by start, each file starts at most
  ``max_gap_s`` after the files before it end (split bags follow each other, separate
  sonar/odometry bags overlap); a larger gap means separate recordings, whose odometry
  would not line up: refused, naming both files and their spans;
* a message that is in two files with the same topic, log time and bytes (a bag copied
  into two, latched ``/tf_static`` repeated at every split) is read once: counted in
  :attr:`MultiSource.notes`, never mapped twice;
* what is lost in a damaged file (a split cut by power loss) is reported per file, and
  the bytes lost are summed; a damaged file with no intact message adds only its loss. A
  file that holds no messages and is not damaged is refused.

Streaming stays lazy and bounded: each file streams its own batches (one chunk at a
time); the files' streams are merged by log time (a k-way merge on a heap) chunk by chunk
(the batches of one chunk, one per topic, stay together: the reader puts them in log
order together), cutting a chunk where another file's next chunk begins
(``MERGE_SLACK_NS`` later, so that two overlapping files alternate in pieces of about
two seconds, not message by message: each piece costs a decoder call; the pipeline's 2 s
reorder window absorbs the 1 s, with 1 s to spare for header stamps lagging log time).
"""

from __future__ import annotations

import heapq
from collections import deque
from collections.abc import Collection, Iterator, Sequence
from dataclasses import replace
from datetime import UTC, datetime

import numpy as np

from formats.contract import LogFile
from formats.errors import FormatError
from formats.ros.source import Connection, MessageSource, RawBatch, messages_lost
from formats.storage.location import Location, joined

#: Two files' streams may alternate this far out of log order (the pipeline reorders
#: readings within 2 s; poses of one topic never come from two overlapping files). Half
#: of it made the pieces half as long and reading sonar + odometry files 1.7x slower.
MERGE_SLACK_NS = 1_000_000_000
#: How long emitted messages of a topic are remembered to recognise a duplicate from
#: another file (beyond the merge slack): duplicates have equal log times.
_DEDUP_HORIZON_NS = 2 * MERGE_SLACK_NS


def span_text(start_ns: int | None, end_ns: int | None) -> str:
    """``12:00:00.000-12:05:00.000 UTC`` (the date too when it is not the same day)."""
    if start_ns is None or end_ns is None:
        return "no messages"
    a = datetime.fromtimestamp(start_ns / 1e9, tz=UTC)
    b = datetime.fromtimestamp(end_ns / 1e9, tz=UTC)
    day = f"{a:%Y-%m-%d} " if a.date() == b.date() else ""
    tail = f"{b:%H:%M:%S}.{b.microsecond // 1000:03d}" if day else f"{b:%Y-%m-%d %H:%M:%S}"
    return f"{day}{a:%H:%M:%S}.{a.microsecond // 1000:03d}-{tail} UTC"


class MultiSource:
    """Several sources of one recording, read as one (see the module docstring).

    ``sources`` are open sources of one format; they are ordered by start time (then
    path), so the order the files were named in does not change the result. The
    sources are closed by :meth:`close` (also when this constructor refuses them).
    """

    def __init__(self, sources: Sequence[MessageSource], *, max_gap_s: float) -> None:
        try:
            if len(sources) < 2:
                raise ValueError("MultiSource needs at least two sources")
            self._sources = sorted(
                sources,
                key=lambda s: (s.start_ns is None, s.start_ns or 0, str(s.path)),
            )
            first = self._sources[0]
            # For messages about the whole recording: every file, in time order.
            self.path: Location = joined([s.path for s in self._sources])
            self.format_name = first.format_name
            self._check_formats()
            self._check_time(max_gap_s)
            self._merge_connections()
        except BaseException:
            for s in sources:
                s.close()
            raise
        self._duplicates: dict[str, int] = {}
        self._read = False  # a pass over the messages has counted the duplicates

    # -- MessageSource ---------------------------------------------------------------------

    @property
    def connections(self) -> list[Connection]:
        return list(self._connections.values())

    @property
    def start_ns(self) -> int | None:
        starts = [s.start_ns for s in self._sources if s.start_ns is not None]
        return min(starts) if starts else None

    @property
    def end_ns(self) -> int | None:
        ends = [s.end_ns for s in self._sources if s.end_ns is not None]
        return max(ends) if ends else None

    @property
    def warnings(self) -> list[str]:
        """Every file's losses, each line prefixed with the file's name."""
        return [f"{s.path.name}: {w}" for s in self._sources for w in s.warnings]

    @property
    def bytes_lost(self) -> int:
        return sum(s.bytes_lost for s in self._sources)

    @property
    def messages_lost(self) -> int:
        return sum(messages_lost(s) for s in self._sources)

    @property
    def files(self) -> list[LogFile]:
        """The files in time order, with their spans and message counts."""
        return [
            LogFile(str(s.path), s.start_ns, s.end_ns, sum(c.count for c in s.connections))
            for s in self._sources
        ]

    @property
    def duplicates_read_once(self) -> int:
        """Messages met in more than one file (same topic, log time, bytes), read once."""
        return sum(self._duplicates.values())

    @property
    def notes(self) -> list[str]:
        """What reading the files as one did besides merging (duplicates read once); before
        any pass, files that overlap in time on a topic they share (so the counts, summed
        per file, may hold a message twice)."""
        if self._duplicates:
            what = ", ".join(f"{n} on {t}" for t, n in sorted(self._duplicates.items()))
            return [f"messages in more than one file (same topic, log time and bytes) read "
                    f"once: {what}"]
        pair = None if self._read else self._overlapping_pair()
        if pair is None:
            return []
        return [f"{pair[0].path.name} and {pair[1].path.name} overlap in time on a topic they "
                f"share: a message stored in both counts twice in these per-file counts; "
                f"reading the log keeps one copy (duplicates_read_once in metrics.json)"]

    def _overlapping_pair(self) -> tuple[MessageSource, MessageSource] | None:
        """The first two files (in time order) whose spans overlap and share a topic."""
        topics = [{c.topic for c in s.connections} for s in self._sources]
        for i, a in enumerate(self._sources):
            for j in range(i + 1, len(self._sources)):
                b = self._sources[j]
                if None in (a.end_ns, b.start_ns) or not topics[i] & topics[j]:
                    continue
                if b.start_ns <= a.end_ns:  # type: ignore[operator]
                    return a, b
        return None

    def close(self) -> None:
        for s in self._sources:
            s.close()

    def __enter__(self) -> MultiSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def raw_batches(self, connection_ids: Collection[int]) -> Iterator[RawBatch]:
        """The files' messages of the given connections merged by log time (see the
        module docstring); duplicates across files are dropped."""
        wanted = {int(c) for c in connection_ids}
        streams: list[Iterator[RawBatch]] = []
        for s, local in zip(self._sources, self._local, strict=True):
            ids = [sid for sid, cid in local.items() if cid in wanted]
            streams.append(self._renamed(s.raw_batches(ids), local) if ids else iter(()))
        dedup = _Dedup(self._shared_topics, self._duplicates)
        for index, piece in _merge_by_time(streams, MERGE_SLACK_NS):
            kept = dedup.filter(index, piece)
            if kept is not None:
                yield kept
        self._read = True

    # -- opening -----------------------------------------------------------------------

    def _names(self, *sources: MessageSource) -> str:
        return " and ".join(str(s.path) for s in sources)

    def _check_formats(self) -> None:
        for s in self._sources[1:]:
            if s.format_name != self.format_name:
                first = self._sources[0]
                raise FormatError(
                    f"files of one recording must have one format: {first.path} is "
                    f"{first.format_name}, {s.path} is {s.format_name}"
                )

    def _check_time(self, max_gap_s: float) -> None:
        """Sorted by start, each file begins within ``max_gap_s`` of the end of the files
        before it (they follow each other or overlap)."""
        for s in self._sources:
            # A file damaged beyond its first message adds its loss, not a span.
            if (s.start_ns is None or s.end_ns is None) and not s.warnings:
                raise FormatError(
                    "holds no messages: it cannot be part of a recording read from "
                    "several files", s.path,
                )
        spans = [s for s in self._sources if s.start_ns is not None]
        if not spans:
            return
        max_gap_ns = round(max_gap_s * 1e9)
        latest = spans[0]
        for s in spans[1:]:
            assert s.start_ns is not None and latest.end_ns is not None
            gap = s.start_ns - latest.end_ns
            if gap > max_gap_ns:
                raise FormatError(
                    f"{latest.path} ({span_text(latest.start_ns, latest.end_ns)}) and "
                    f"{s.path} ({span_text(s.start_ns, s.end_ns)}) are {gap / 1e9:.1f} s "
                    f"apart: not one recording (files of one recording overlap or follow "
                    f"each other within input.max_file_gap_s = {max_gap_s:g} s)"
                )
            if s.end_ns is not None and s.end_ns > (latest.end_ns or 0):
                latest = s

    def _merge_connections(self) -> None:
        """One connection per (topic, type, encoding, definition) over all files, new ids;
        a topic with two message types is refused."""
        self._local: list[dict[int, int]] = []  # per source: its id → ours
        merged: dict[tuple[str, str, str, str], Connection] = {}
        type_of: dict[str, tuple[str, MessageSource]] = {}
        files_of: dict[str, set[int]] = {}
        for index, s in enumerate(self._sources):
            local: dict[int, int] = {}
            for c in s.connections:
                seen = type_of.setdefault(c.topic, (c.msgtype, s))
                if seen[0] != c.msgtype:
                    raise FormatError(
                        f"topic {c.topic} is {seen[0]} in {seen[1].path} but {c.msgtype} in "
                        f"{s.path}: files of one recording must agree on a topic's type"
                    )
                key = (c.topic, c.msgtype, c.encoding, c.msgdef)
                have = merged.get(key)
                if have is None:
                    merged[key] = replace(c, id=len(merged))
                else:
                    merged[key] = replace(have, count=have.count + c.count)
                local[c.id] = merged[key].id
                files_of.setdefault(c.topic, set()).add(index)
            self._local.append(local)
        self._connections = {c.id: c for c in sorted(merged.values(), key=lambda c: c.id)}
        self._shared_topics = frozenset(t for t, f in files_of.items() if len(f) > 1)

    def _renamed(self, batches: Iterator[RawBatch], local: dict[int, int]) -> Iterator[RawBatch]:
        for raw in batches:
            conn = self._connections[local[raw.connection.id]]
            yield RawBatch(conn, raw.log_time_ns, raw.buffer, raw.offsets, raw.lengths)


def _merge_by_time(
    streams: Sequence[Iterator[RawBatch]], slack_ns: int
) -> Iterator[tuple[int, RawBatch]]:
    """A k-way merge of the streams by log time, lazily: ``(stream index, batch)``.

    The unit is a file's chunk: the consecutive batches that share one buffer (one per
    topic), which the reader merges into log order together. Each stream stays in its own
    order. The stream whose next chunk starts first gives every batch of it up to
    ``slack_ns`` past the start of the next stream's chunk (one after the other, so they
    still form one chunk for the reader); the rest (slices of the same buffer) waits its
    turn. Ties go to the lower index.
    """
    chunks = [_chunks(s) for s in streams]
    heads: dict[int, list[RawBatch]] = {}
    heap: list[tuple[int, int]] = []

    def advance(i: int) -> None:
        head = next(chunks[i], None)
        if head is None:
            heads.pop(i, None)
            return
        heads[i] = head
        heapq.heappush(heap, (_start(head), i))

    for i in range(len(streams)):
        advance(i)
    while heap:
        _, i = heapq.heappop(heap)
        head = heads[i]
        if not heap:
            for raw in head:
                yield i, raw
            advance(i)
            continue
        limit = heap[0][0] + slack_ns
        now: list[RawBatch] = []
        rest: list[RawBatch] = []
        for raw in head:
            # A batch is in log order: its messages up to the limit are a prefix (the
            # batch that starts the chunk gives at least one: it started first).
            n = int(np.searchsorted(np.maximum.accumulate(raw.log_time_ns), limit, "right"))
            if n:
                now.append(raw if n == len(raw) else _slice(raw, 0, n))
            if n < len(raw):
                rest.append(_slice(raw, n, len(raw)))
        for raw in now:
            yield i, raw
        if rest:
            heads[i] = rest
            heapq.heappush(heap, (_start(rest), i))
        else:
            advance(i)


def _chunks(batches: Iterator[RawBatch]) -> Iterator[list[RawBatch]]:
    """Consecutive non-empty batches that share one buffer (one chunk), as lists."""
    group: list[RawBatch] = []
    for raw in batches:
        if not len(raw):
            continue
        if group and raw.buffer is not group[0].buffer:
            yield group
            group = []
        group.append(raw)
    if group:
        yield group


def _start(chunk: list[RawBatch]) -> int:
    """When a chunk starts: the earliest first message of its batches. The first, not the
    least: the merge takes a batch's prefix up to a limit, and a damaged batch out of
    order (a corrupt stamp) must still give its first message, or the merge stalls."""
    return min(int(raw.log_time_ns[0]) for raw in chunk)


def _slice(raw: RawBatch, a: int, b: int) -> RawBatch:
    """Messages ``a:b`` of a batch (views of the same buffer)."""
    return RawBatch(raw.connection, raw.log_time_ns[a:b], raw.buffer, raw.offsets[a:b],
                    raw.lengths[a:b])


class _Dedup:
    """Drops a message another file already gave (same topic, log time and bytes).

    Only topics that are in more than one file are checked. Per topic, the pieces emitted
    in the last ``_DEDUP_HORIZON_NS`` are kept (views of their chunk buffers); a new
    piece's messages whose log time equals one of another file's are compared byte for
    byte. Split bags that follow each other share no log time: nothing is compared.
    """

    def __init__(self, shared: frozenset[str], counts: dict[str, int]) -> None:
        self._shared = shared
        self._recent: dict[str, deque[tuple[int, RawBatch]]] = {}
        self._counts = counts
        self._pass_counts: dict[str, int] = {}

    def filter(self, index: int, raw: RawBatch) -> RawBatch | None:
        topic = raw.connection.topic
        if topic not in self._shared:
            return raw
        recent = self._recent.setdefault(topic, deque())
        t = raw.log_time_ns
        lo = int(t.min())
        while recent and int(recent[0][1].log_time_ns.max()) < lo - _DEDUP_HORIZON_NS:
            recent.popleft()
        others = [(j, r) for j, r in recent if j != index]
        keep: np.ndarray | None = None
        if others:
            times = np.concatenate([r.log_time_ns for _, r in others])
            candidates = np.flatnonzero(np.isin(t, times))
            if candidates.size:
                seen = {
                    (int(r.log_time_ns[k]), r.message(k))
                    for _, r in others
                    for k in np.flatnonzero(np.isin(r.log_time_ns, t[candidates])).tolist()
                }
                dup = [k for k in candidates.tolist() if (int(t[k]), raw.message(k)) in seen]
                if dup:
                    keep = np.ones(len(raw), bool)
                    keep[dup] = False
                    n = self._pass_counts.get(topic, 0) + len(dup)
                    self._pass_counts[topic] = n
                    # Every pass meets the same duplicates: count them once.
                    self._counts[topic] = max(self._counts.get(topic, 0), n)
        recent.append((index, raw))
        if keep is None:
            return raw
        if not keep.any():
            return None
        return RawBatch(raw.connection, raw.log_time_ns[keep], raw.buffer, raw.offsets[keep],
                        raw.lengths[keep])
