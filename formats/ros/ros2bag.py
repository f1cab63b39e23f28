"""ROS 2 bags (rosbag2: sqlite3 or MCAP storage) as a :class:`MessageSource`.

A bag is a directory with ``metadata.yaml`` (versions 4-9) and one or more storage files,
or a single ``.db3`` / ``.mcap`` file (optionally ``.zstd``-compressed) read without one.
Topics and their ids always come from the storage files themselves: metadata topic
order does not match the storage ids in real bags. Split bags are read file by file in
``relative_file_paths`` order (sorted names without metadata); topics are merged across
files by (name, type, definition). Compression: whole files (``compression_mode: FILE``) are
decompressed to a temporary directory; per-message zstd (``MESSAGE``) on the fly.
"""

from __future__ import annotations

import os
import re
import shutil
import sqlite3
import tempfile
import weakref
from collections.abc import Collection, Iterator
from dataclasses import replace
from pathlib import Path, PurePosixPath
from typing import Any, Protocol
from urllib.parse import quote

import numpy as np
import yaml

from formats.errors import FormatError
from formats.path_text import path_text_problem, shown
from formats.ros.inflate import MAX_RATIO, ChunkError, inflate_message
from formats.ros.mcap_source import McapSource
from formats.ros.source import (
    Connection,
    Encoding,
    RawBatch,
    SourceAccessors,
    messages_lost,
    normalize_msgtype,
)
from formats.ros.sqlite_salvage import DAMAGE_ERRORS, ROW_ERRORS, Salvage
from formats.storage.location import Location, Url, as_location
from formats.text_file import read_text

_STORAGE_SUFFIXES = {".db3": "sqlite3", ".mcap": "mcap"}
# Rows fetched from sqlite per batch: bounded memory whatever the bag size.
SQLITE_BATCH_ROWS = 4096



def _inside_bag(bag: Location, name: str, meta: Location) -> Location:
    """The storage file ``name`` of ``metadata.yaml``, which must lie inside the bag
    directory (no absolute path, no ``..``, no symlink leading out): FormatError else."""
    problem = path_text_problem(name)
    if problem is not None:
        raise FormatError(f"metadata names a storage file {shown(name)} that {problem}", meta)
    if isinstance(bag, Url):  # a prefix: no symlinks, only the name can lead out
        parts = PurePosixPath(name).parts
        if name.startswith("/") or ".." in parts or "://" in name or not parts:
            raise FormatError(f"metadata names a storage file outside the bag: {name!r}", meta)
        return bag / name
    p = bag / name
    try:
        inside = not Path(name).is_absolute() and p.resolve().is_relative_to(bag.resolve())
    except (OSError, RuntimeError, ValueError):
        inside = False
    if not inside:
        raise FormatError(f"metadata names a storage file outside the bag: {name!r}", meta)
    return p


class _StorageFile(Protocol):
    @property
    def path(self) -> Location: ...

    @property
    def connections(self) -> list[Connection]: ...

    @property
    def start_ns(self) -> int | None: ...

    @property
    def end_ns(self) -> int | None: ...

    @property
    def warnings(self) -> list[str]: ...

    @property
    def bytes_lost(self) -> int: ...

    def raw_batches(self, connection_ids: Collection[int]) -> Iterator[RawBatch]: ...

    def close(self) -> None: ...


class Sqlite3File(SourceAccessors):
    """One rosbag2 ``.db3`` file (old schema without definitions, or with
    ``message_definitions``); connection ids are the ``topics`` table ids."""

    def __init__(self, path: Path, display: Location | None = None) -> None:
        self.path = path
        self._name = display or path  # the path to name in errors (not a temp copy)
        self._warnings: list[str] = []
        self._messages_lost = 0
        self._salvage = ""  # why the rows are read by id ranges (a damaged database)
        if not path.is_file() or path.stat().st_size == 0:
            what = "empty file (0 bytes)" if path.is_file() else "missing file"
            raise FormatError(f"{what}, not a rosbag2 sqlite3 database", self._name)
        # Read-only and immutable: sqlite neither writes -wal/-shm files next to the user's
        # bag nor needs write access to its directory (archive mounts, read-only binds).
        uri = f"file:{quote(os.fsencode(path.resolve()))}?mode=ro&immutable=1"
        try:
            self._db = sqlite3.connect(uri, uri=True, check_same_thread=False)
        except sqlite3.Error as err:
            raise FormatError(f"cannot open sqlite3 database: {err}", self._name) from err
        try:
            self._load()
        # A corrupt database can also hold values of the wrong type (int('') fails).
        except ROW_ERRORS as err:
            self._db.close()
            raise FormatError(
                f"not a readable rosbag2 sqlite3 database: {err}", self._name
            ) from err
        except BaseException:
            self._db.close()
            raise

    def _load(self) -> None:
        db = self._db
        tables = {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if not {"topics", "messages"} <= tables:
            raise FormatError(
                f"not a rosbag2 database: tables {sorted(tables)}, expected topics and messages",
                self._name,
            )
        defs: dict[str, tuple[str, str]] = {}
        if "message_definitions" in tables:
            try:
                for typ, enc, text in db.execute(
                    "SELECT topic_type, encoding, encoded_message_definition"
                    " FROM message_definitions"
                ):
                    if typ and enc in ("ros2msg", "ros2idl"):
                        defs[str(typ)] = (str(text), str(enc))
            except DAMAGE_ERRORS as err:  # the built-in definitions of known types remain
                defs.clear()
                self._warnings.append(f"message definitions unreadable ({_reason(err)});"
                                      " they are not used")
        try:
            counts = dict(db.execute("SELECT topic_id, COUNT(*) FROM messages GROUP BY topic_id"))
            t0, t1 = db.execute("SELECT MIN(timestamp), MAX(timestamp) FROM messages").fetchone()
        except DAMAGE_ERRORS as err:  # damaged pages: the rows sqlite can still read
            counts, t0, t1 = self._count_by_rows(err)
        self._start = None if t0 is None else int(t0)
        self._end = None if t1 is None else int(t1)
        self._connections: dict[int, Connection] = {}
        for tid, name, typ, fmt in db.execute(
            "SELECT id, name, type, serialization_format FROM topics ORDER BY id"
        ):
            msgdef, deffmt = defs.get(str(typ), ("", ""))
            self._connections[int(tid)] = Connection(
                id=int(tid),
                topic=str(name),
                msgtype=normalize_msgtype(str(typ)),
                encoding=_encoding(str(fmt)),
                msgdef=msgdef,
                msgdef_format=deffmt,
                count=int(counts.get(tid, 0)),
            )

    def _count_by_rows(self, err: Exception) -> tuple[dict[int, int], int | None,
                                                          int | None]:
        """Per-topic counts and the time span from the rows sqlite can still read
        (:class:`~formats.ros.sqlite_salvage.Salvage`); the error again when it cannot."""
        salvage = Salvage(self._db)
        if salvage.span is None:
            raise err
        counts: dict[int, int] = {}
        t0: int | None = None
        t1: int | None = None
        for rows in salvage.rows("topic_id, timestamp, id", "", ()):
            tids = np.fromiter((r[0] for r in rows), np.int64, len(rows))
            times = np.fromiter((r[1] for r in rows), np.int64, len(rows))
            for tid, n in zip(*np.unique(tids, return_counts=True), strict=True):
                counts[int(tid)] = counts.get(int(tid), 0) + int(n)
            t0 = int(times.min()) if t0 is None else min(t0, int(times.min()))
            t1 = int(times.max()) if t1 is None else max(t1, int(times.max()))
        self._salvage = f"database is damaged ({_reason(err)})"
        return counts, t0, t1

    def raw_batches(self, connection_ids: Collection[int]) -> Iterator[RawBatch]:
        """Messages ordered by (timestamp, id), SQLITE_BATCH_ROWS rows at a time; each page
        becomes one batch per topic sharing one buffer. In a damaged database the rows
        after the damage are read by id ranges around what sqlite cannot read (each
        range in time order); the rows lost are counted."""
        ids = sorted({int(c) for c in connection_ids} & set(self._connections))
        if not ids:
            return
        if self._salvage:
            yield from self._salvaged(ids, self._salvage, None)
            return
        marks = ",".join("?" * len(ids))
        done = 0
        last: tuple[int, int] | None = None
        try:
            # The timestamp index stores (timestamp, rowid): this streams without sorting.
            cur = self._db.execute(
                f"SELECT topic_id, timestamp, data, id FROM messages WHERE topic_id IN ({marks})"
                " ORDER BY timestamp, id",
                ids,
            )
        except DAMAGE_ERRORS as err:
            yield from self._salvaged(ids, f"cannot read messages ({_reason(err)})", None)
            return
        while True:
            try:
                rows = cur.fetchmany(SQLITE_BATCH_ROWS)
                if not rows:
                    return
                batches = list(self._batches(rows, ids))
            # corrupt pages (DAMAGE_ERRORS); TypeError/ValueError: a corrupt row whose
            # columns hold values of the wrong type (text data, NULL, ...).
            except ROW_ERRORS as err:
                why = f"database is corrupt after {done} messages ({_reason(err)})"
                yield from self._salvaged(ids, why, last)
                return
            done += len(rows)
            last = (int(rows[-1][1]), int(rows[-1][3]))
            yield from batches

    def _batches(self, rows: list[tuple[Any, ...]], ids: list[int]) -> Iterator[RawBatch]:
        """Rows (topic_id, timestamp, data, ...) as one batch per topic of ``ids``."""
        tids = np.fromiter((r[0] for r in rows), np.int64, len(rows))
        times = np.fromiter((r[1] for r in rows), np.int64, len(rows))
        blobs = [r[2] for r in rows]
        lengths = np.fromiter(map(len, blobs), np.int64, len(rows))
        joined = b"".join(blobs)
        offsets = np.cumsum(lengths) - lengths
        buf = np.frombuffer(joined, np.uint8)
        for tid in ids:
            sel = np.flatnonzero(tids == tid)
            if sel.size:
                yield RawBatch(self._connections[tid], times[sel], buf, offsets[sel], lengths[sel])

    def _salvaged(self, ids: list[int], why: str,
                  after: tuple[int, int] | None) -> Iterator[RawBatch]:
        """The rows of topics ``ids`` read by id ranges (after (timestamp, id) ``after``:
        those were read already); the loss said once in :attr:`warnings`."""
        salvage = Salvage(self._db)
        if salvage.span is None:
            self._warn_once(f"{why}; the rest of this file is lost", 0)
            return
        marks = ",".join("?" * len(ids))
        for rows in salvage.rows("topic_id, timestamp, data, id", f"topic_id IN ({marks})",
                                 ids):
            if after is not None:
                rows = [r for r in rows if (int(r[1]), int(r[3])) > after]
            rows.sort(key=lambda r: (int(r[1]), int(r[3])))
            try:
                batches = list(self._batches(rows, ids)) if rows else []
            except (TypeError, ValueError, OverflowError):  # a row of wrong types
                salvage.rows_lost += len(rows)
                continue
            yield from batches
        self._warn_once(f"{why}; the rest read row by row: {salvage.rows_lost} rows sqlite"
                        " cannot read are lost", salvage.rows_lost)

    def _warn_once(self, line: str, lost: int) -> None:
        """A loss said and counted once (every pass over the bag meets it again)."""
        if line not in self._warnings:
            self._warnings.append(line)
            self._messages_lost += lost

    def close(self) -> None:
        self._db.close()


def _encoding(fmt: str) -> Encoding:
    if fmt in ("cdr", "ros1"):
        return fmt  # type: ignore[return-value]
    return "other"


class Ros2BagSource(SourceAccessors):
    """A rosbag2 bag directory, or a single storage file.

    ``format_name`` is ``'ros2-sqlite3'`` or ``'ros2-mcap'``.
    """

    def __init__(self, path: str | Location) -> None:
        self.path = as_location(path)
        self._warnings: list[str] = []
        self.notes: list[str] = []  # for `info`: storage files downloaded to read them
        self._files: list[_StorageFile] = []
        self._tmpdir: Path | None = None
        self._finalizer: Any = None
        try:
            self._open()
        except BaseException:
            self.close()
            raise

    # -- opening -------------------------------------------------------------------------

    def _open(self) -> None:
        path = self.path
        compression_mode = ""
        if path.is_dir():
            meta = path / "metadata.yaml"
            if meta.is_file():
                storage, names, compression_mode = self._read_metadata(meta)
                files = [_inside_bag(path, n, meta) for n in names]
            else:
                files = sorted(
                    (p for p in path.iterdir() if _storage_of(p) is not None),
                    key=_natural_key,
                )
                if not files:
                    raise FormatError("no metadata.yaml and no .db3/.mcap files", path)
                kinds = {_storage_of(p) for p in files}
                if len(kinds) > 1:
                    raise FormatError("both .db3 and .mcap files and no metadata.yaml", path)
                storage = str(kinds.pop())
        elif path.is_file():
            kind = _storage_of(path)
            if kind is None:
                raise FormatError(
                    "not a ROS 2 bag: expected a directory, .db3, .mcap (or .zstd of those)",
                    path,
                )
            storage, files = kind, [path]
        else:
            raise FormatError("no such file or directory", path)
        for f in files:
            if not f.is_file():
                raise FormatError(f"storage file {f.name} listed in the bag is missing", f)
        self.format_name = f"ros2-{storage}"
        self._message_zstd = compression_mode == "MESSAGE"
        for f in files:
            local = self._decompressed(f) if f.suffix == ".zstd" else f
            if isinstance(local, Url):
                if storage == "mcap":  # read by ranges where it is
                    self._files.append(McapSource(local))
                    continue
                local = self._downloaded(local)
            self._files.append(
                McapSource(local) if storage == "mcap" else Sqlite3File(local, display=f)
            )
        self._merge()

    def _read_metadata(self, meta: Location) -> tuple[str, list[str], str]:
        try:
            doc = yaml.safe_load(read_text(meta, "rosbag2 metadata",
                                           errors=(FormatError, FormatError)))
            info = doc["rosbag2_bagfile_information"]
            version = int(info["version"])
            storage = str(info.get("storage_identifier") or "sqlite3")
            names = [str(n) for n in info["relative_file_paths"]]
            mode = str(info.get("compression_mode") or "").upper()
            fmt = str(info.get("compression_format") or "")
        except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError, RecursionError) as err:
            raise FormatError(f"unreadable rosbag2 metadata ({_reason(err)})", meta) from err
        if version < 1 or version > 9:
            raise FormatError(f"unsupported rosbag2 metadata version {version}", meta)
        if storage not in ("sqlite3", "mcap"):
            raise FormatError(f"unsupported storage {storage!r} (sqlite3, mcap)", meta)
        if mode not in ("", "NONE", "FILE", "MESSAGE"):
            raise FormatError(f"unsupported compression_mode {mode!r}", meta)
        if mode in ("FILE", "MESSAGE") and fmt != "zstd":
            raise FormatError(f"unsupported compression_format {fmt!r} (zstd)", meta)
        return storage, names, mode

    def _temp_dir(self) -> Path:
        """This source's temporary directory, removed on close (or when it is collected)."""
        if self._tmpdir is None:
            self._tmpdir = Path(tempfile.mkdtemp(prefix="sonarmap-ros2-"))
            self._finalizer = weakref.finalize(self, shutil.rmtree, self._tmpdir, True)
        return self._tmpdir

    def _downloaded(self, src: Url) -> Path:
        """A storage file at a URL copied into the temp dir (sqlite needs a local file)."""
        dst = self._temp_dir() / src.name
        src.download(dst)
        self.notes.append(f"{src.name}: a sqlite3 storage file is read from a local copy: "
                          f"downloaded from {src} to a temporary file, removed when closed")
        return dst

    def _decompressed(self, src: Location) -> Path:
        """A zstd-compressed storage file decompressed into this source's temp dir."""
        import zstandard

        dst = self._temp_dir() / src.name[: -len(".zstd")]
        # At most what zstd can inflate this many bytes to (formats/ros/inflate.py): a
        # small file must not fill the disk.
        limit = src.stat().st_size * MAX_RATIO["zstd"] + (1 << 20)
        written = 0
        try:
            with src.open("rb") as fin, dst.open("wb") as fout:
                reader = zstandard.ZstdDecompressor().stream_reader(fin, read_across_frames=True)
                while piece := reader.read(1 << 20):
                    written += len(piece)
                    if written > limit:
                        raise FormatError(
                            f"zstd file inflates to more than {limit} bytes, more than zstd"
                            f" can encode in {src.stat().st_size} bytes (corrupt)", src)
                    fout.write(piece)
        except (OSError, zstandard.ZstdError) as err:
            raise FormatError(f"cannot decompress zstd file ({_reason(err)})", src) from err
        if dst.stat().st_size == 0:
            raise FormatError("cannot decompress zstd file (no data in it)", src)
        return dst

    def _merge(self) -> None:
        """One connection per (topic, type, encoding, definition) over all files; ids from
        the first file that has it, new ids after the largest for ones that appear later."""
        self._map: list[dict[int, int]] = []  # per file: storage id → our id
        merged: dict[tuple[str, str, str, str], Connection] = {}
        for f in self._files:
            taken = {c.id for c in merged.values()}
            local: dict[int, int] = {}
            for c in f.connections:
                # The definition is part of the key: decoders must see each file's own.
                key = (c.topic, c.msgtype, c.encoding, c.msgdef)
                have = merged.get(key)
                if have is None:
                    cid = c.id if c.id not in taken else max(taken | {0}) + 1
                    taken.add(cid)
                    merged[key] = replace(c, id=cid)
                else:
                    merged[key] = replace(have, count=have.count + c.count)
                local[c.id] = merged[key].id
            self._map.append(local)
        self._connections = {c.id: c for c in sorted(merged.values(), key=lambda c: c.id)}
        starts = [f.start_ns for f in self._files if f.start_ns is not None]
        ends = [f.end_ns for f in self._files if f.end_ns is not None]
        self._start = min(starts) if starts else None
        self._end = max(ends) if ends else None

    # -- MessageSource -------------------------------------------------------------------

    @property
    def bytes_lost(self) -> int:
        return self._bytes_lost + sum(f.bytes_lost for f in self._files)

    @property
    def messages_lost(self) -> int:
        return sum(messages_lost(f) for f in self._files)

    @property
    def warnings(self) -> list[str]:
        out = list(self._warnings)
        for f in self._files:
            out += [f"{f.path.name}: {w}" for w in f.warnings]
        return out

    def raw_batches(self, connection_ids: Collection[int]) -> Iterator[RawBatch]:
        """Messages of the given connections, file by file, in log order within a file."""
        wanted = {int(c) for c in connection_ids}
        for f, local in zip(self._files, self._map, strict=True):
            ids = [sid for sid, cid in local.items() if cid in wanted]
            if not ids:
                continue
            for raw in f.raw_batches(ids):
                conn = self._connections[local[raw.connection.id]]
                if self._message_zstd:
                    raw = self._decompress_messages(raw, f.path.name)
                yield RawBatch(conn, raw.log_time_ns, raw.buffer, raw.offsets, raw.lengths)

    def _decompress_messages(self, raw: RawBatch, name: str) -> RawBatch:
        """The batch with every message zstd-decompressed (``compression_mode: MESSAGE``),
        each within the bound of formats/ros/inflate.py; a message that does not inflate
        is skipped and recorded as a loss."""
        out: list[bytes] = []
        keep: list[int] = []
        for i in range(len(raw)):
            t = int(raw.log_time_ns[i])
            try:
                out.append(inflate_message(raw.message(i), f"message at log time {t} ns"))
                keep.append(i)
            except ChunkError as err:
                line = f"{name}: topic {raw.connection.topic}: {err}; message skipped"
                if line not in self._warnings:
                    self._warnings.append(line)
                    self._bytes_lost += int(raw.lengths[i])
        lengths = np.fromiter(map(len, out), np.int64, len(out))
        return RawBatch(
            raw.connection,
            raw.log_time_ns[keep],
            np.frombuffer(b"".join(out), np.uint8),
            np.cumsum(lengths) - lengths,
            lengths,
        )

    def close(self) -> None:
        for f in self._files:
            f.close()
        self._files = []
        if self._finalizer is not None:
            self._finalizer()

    def __enter__(self) -> Ros2BagSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _storage_of(p: Location) -> str | None:
    name = p.name[: -len(".zstd")] if p.name.endswith(".zstd") else p.name
    return _STORAGE_SUFFIXES.get(Path(name).suffix) if p.is_file() else None


def _natural_key(p: Location) -> list[Any]:
    """bag_2 before bag_10."""
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", p.name)]


def _reason(err: BaseException) -> str:
    return " ".join((str(err) or type(err).__name__).split())
