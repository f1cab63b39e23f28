"""The container layer of ROS logs: serialized messages in, without interpreting them.

A :class:`MessageSource` is a ROS 1 bag, a ROS 2 bag (sqlite3 or MCAP storage) or a
standalone MCAP file. It lists its topics and streams :class:`RawBatch` es — the raw bytes
of many messages of one topic, as one buffer plus offsets — in log order, chunk by chunk,
so decoders can work on whole batches with numpy instead of one message at a time.

Decoding (``formats/ros/decode_*.py``) and interpretation into the reader contract
(``formats/ros/reader.py``) are separate layers on top of this one.
"""

from __future__ import annotations

from collections.abc import Collection, Iterator
from dataclasses import dataclass
from typing import BinaryIO, Literal, Protocol, Self

import numpy as np
import numpy.typing as npt

from formats.errors import FormatError
from formats.storage.location import Location

# "other": an MCAP channel in another encoding (json, protobuf, ...): listed, not decodable.
Encoding = Literal["ros1", "cdr", "other"]


@dataclass(frozen=True)
class Connection:
    """A topic as a container stores it: name, type, encoding and message definition.

    ``msgdef`` is the definition text the log carries (ROS 1 ``message_definition``,
    MCAP schema data, ROS 2 ``type_description``), ``''`` when the log carries none (then
    decoders fall back to a default typestore). ``msgdef_format`` is ``'ros1msg'``,
    ``'ros2msg'``, ``'ros2idl'`` or ``''``. Several connections may share one topic.
    """

    id: int
    topic: str
    msgtype: str  # normalised ROS 2 style: 'sensor_msgs/msg/Range'
    encoding: Encoding
    msgdef: str
    msgdef_format: str
    count: int  # messages stored for this connection (from the index/statistics)
    md5sum: str = ""  # ROS 1 only


@dataclass(frozen=True)
class RawBatch:
    """Serialized messages of one connection: message ``i`` is
    ``buffer[offsets[i] : offsets[i] + lengths[i]]``, logged at ``log_time_ns[i]``."""

    connection: Connection
    log_time_ns: npt.NDArray[np.int64]
    buffer: npt.NDArray[np.uint8]
    offsets: npt.NDArray[np.int64]
    lengths: npt.NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.log_time_ns.shape[0])

    def message(self, i: int) -> bytes:
        o = int(self.offsets[i])
        return self.buffer[o : o + int(self.lengths[i])].tobytes()


def normalize_msgtype(name: str) -> str:
    """ROS 2 style type name: ``'sensor_msgs/Range'`` → ``'sensor_msgs/msg/Range'``;
    anything else unchanged."""
    parts = name.split("/")
    if len(parts) == 2 and all(parts):
        return f"{parts[0]}/msg/{parts[1]}"
    return name


class SourceAccessors:
    """The MessageSource accessors, over the state a source fills in while opening:
    ``_connections`` (by id, in id order), ``_start``/``_end`` (log time, ns) and
    ``_warnings`` (losses found while reading) and ``_bytes_lost`` (bytes of the file that
    could not be read: a truncated end, a cut-off chunk)."""

    _connections: dict[int, Connection]
    _start: int | None
    _end: int | None
    _warnings: list[str]
    _bytes_lost: int = 0
    _messages_lost: int = 0

    @property
    def connections(self) -> list[Connection]:
        return list(self._connections.values())

    @property
    def start_ns(self) -> int | None:
        return self._start

    @property
    def end_ns(self) -> int | None:
        return self._end

    @property
    def warnings(self) -> list[str]:
        return self._warnings

    @property
    def bytes_lost(self) -> int:
        return self._bytes_lost

    @property
    def messages_lost(self) -> int:
        """Messages the index counts in chunks that were lost (in ``connections`` counts)."""
        return self._messages_lost


def messages_lost(source: object) -> int:
    """A source's ``messages_lost`` (0 for a source that does not count them)."""
    return int(getattr(source, "messages_lost", 0))


class MessageSource(Protocol):
    """A ROS log container (ROS 1 bag, ROS 2 bag, MCAP)."""

    path: Location
    format_name: str  # 'ros1', 'ros2-sqlite3', 'ros2-mcap', 'mcap'

    @property
    def connections(self) -> list[Connection]: ...

    @property
    def start_ns(self) -> int | None: ...

    @property
    def end_ns(self) -> int | None: ...

    def raw_batches(self, connection_ids: Collection[int]) -> Iterator[RawBatch]:
        """Messages of the given connections in log order, batched per chunk/connection.

        Truncated or corrupt tails: yield what is intact, then record the loss in
        ``self.warnings`` (one line each) instead of raising; a log whose header or index
        is unusable raises :class:`~formats.errors.FormatError`.
        """
        ...

    @property
    def warnings(self) -> list[str]: ...

    @property
    def bytes_lost(self) -> int: ...

    def close(self) -> None: ...


class FileSource:
    """The life cycle of a source that reads one file: :meth:`_open_file` opens it (a file
    that cannot be opened is a FormatError naming it), keeps its size and runs the
    source's ``_open`` parse, closing the file if that fails; a context manager. A URL is
    read by ranges (:meth:`formats.storage.location.Url.open`)."""

    path: Location
    _file: BinaryIO
    _size: int

    def _open(self) -> None:
        raise NotImplementedError

    def _open_file(self) -> None:
        try:
            self._file = self.path.open("rb")
        except OSError as err:
            raise FormatError(f"cannot open: {err.strerror or err}", self.path) from err
        try:
            self._size = self.path.stat().st_size
            self._open()
        except BaseException:
            self._file.close()
            raise

    def close(self) -> None:
        """Close the file."""
        self._file.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
