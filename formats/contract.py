"""The one reader contract: every supported log becomes the same typed, columnar stream.

A reader is opened with :func:`formats.open_log` and is a context manager. It yields
**columnar batches** (numpy arrays, never one Python object per message) of three kinds:

* :class:`RangeBatch` — sonar range readings,
* :class:`PoseBatch` — 2-D robot poses of one ``parent → child`` frame pair,
* :class:`MountBatch` — static sensor mounts in the robot base frame.

Conventions (REP 103 / REP 105 / REP 117):

* timestamps are ``int64`` nanoseconds since the epoch (or since the log's own zero for
  logs without absolute time), taken from the message header stamp;
* positions are metres, angles radians, yaw counter-clockwise from +x;
* ranges keep their REP 117 meaning: ``+inf`` = nothing detected, ``-inf`` = too close,
  ``nan`` = erroneous. Readers never drop or clamp readings: the pipeline counts and
  drops them by reason.

Sensors are identified by a small integer ``sensor_id`` that indexes the reader's
append-only ``sensor_names`` list (for ROS logs the ``frame_id`` of the Range message,
for CSV the sensor column), so a batch carries no strings on the hot path.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Literal, Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from formats.arrays import F64, I32, I64
from formats.storage.location import Location

Kind = Literal["ranges", "poses", "mounts"]
ALL_KINDS: tuple[Kind, ...] = ("ranges", "poses", "mounts")


@dataclass(frozen=True)
class RangeBatch:
    """Sonar readings, one row per reading (all arrays have the same length).

    ``scan_id`` is ``-1`` where the log does not group readings into scans; it is set
    when one message carries a whole ring (PointCloud, SonarArray) or a CSV has a scan
    column, so the pipeline's ``explicit`` scan policy can use it.
    ``record_t_ns`` is the time the log recorded the message (bag/MCAP log time), used by
    ``validate`` to measure header-stamp skew; equal to ``t_ns`` where the log has none.
    """

    t_ns: I64
    sensor_id: I32
    range_m: F64
    fov_rad: F64
    min_range_m: F64
    max_range_m: F64
    scan_id: I64
    record_t_ns: I64
    variance: F64  # ROS 2 Range.variance (m²); NaN where the log has none

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    @staticmethod
    def concat(batches: Sequence[RangeBatch]) -> RangeBatch:
        """Concatenate batches column by column (an empty batch for an empty list)."""
        if not batches:
            return empty_range_batch()
        return RangeBatch(
            *(np.concatenate([getattr(b, f) for b in batches]) for f in RANGE_FIELDS)
        )

    def take(self, index: npt.NDArray[np.intp] | npt.NDArray[np.bool_] | slice) -> RangeBatch:
        """Rows selected by an index array, boolean mask or slice."""
        return RangeBatch(*(getattr(self, f)[index] for f in RANGE_FIELDS))


RANGE_FIELDS: tuple[str, ...] = (
    "t_ns",
    "sensor_id",
    "range_m",
    "fov_rad",
    "min_range_m",
    "max_range_m",
    "scan_id",
    "record_t_ns",
    "variance",
)


def empty_range_batch() -> RangeBatch:
    """A batch with no rows and the right dtypes."""
    i64 = np.empty(0, np.int64)
    f64 = np.empty(0, np.float64)
    return RangeBatch(i64, np.empty(0, np.int32), f64, f64, f64, f64, i64, i64, f64)


def make_range_batch(
    t_ns: npt.ArrayLike,
    sensor_id: npt.ArrayLike,
    range_m: npt.ArrayLike,
    fov_rad: npt.ArrayLike,
    min_range_m: npt.ArrayLike,
    max_range_m: npt.ArrayLike,
    *,
    scan_id: npt.ArrayLike | None = None,
    record_t_ns: npt.ArrayLike | None = None,
    variance: npt.ArrayLike | None = None,
) -> RangeBatch:
    """Build a :class:`RangeBatch` with the contract's dtypes, broadcasting scalars."""
    t = np.asarray(t_ns, dtype=np.int64).reshape(-1)
    n = t.shape[0]

    def col(v: npt.ArrayLike | None, dtype: type, fill: float | int) -> np.ndarray:
        if v is None:
            return np.full(n, fill, dtype=dtype)
        return np.broadcast_to(np.asarray(v, dtype=dtype), (n,)).copy()

    return RangeBatch(
        t_ns=t,
        sensor_id=col(sensor_id, np.int32, 0),
        range_m=col(range_m, np.float64, np.nan),
        fov_rad=col(fov_rad, np.float64, np.nan),
        min_range_m=col(min_range_m, np.float64, np.nan),
        max_range_m=col(max_range_m, np.float64, np.nan),
        scan_id=col(scan_id, np.int64, -1),
        record_t_ns=t.copy() if record_t_ns is None else col(record_t_ns, np.int64, 0),
        variance=col(variance, np.float64, np.nan),
    )


@dataclass(frozen=True)
class PoseBatch:
    """2-D poses of ``child_frame`` in ``parent_frame`` (e.g. ``odom → base_link``)."""

    t_ns: I64
    x: F64
    y: F64
    yaw: F64
    parent_frame: str
    child_frame: str
    record_t_ns: I64 | None = None

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])


@dataclass(frozen=True)
class SensorMount:
    """A sensor's pose in the robot base frame (metres, radians)."""

    x: float
    y: float
    yaw: float


@dataclass(frozen=True)
class MountBatch:
    """Static sensor mounts discovered in the log, keyed by sensor name (frame id)."""

    base_frame: str
    mounts: dict[str, SensorMount]

    def __len__(self) -> int:
        return len(self.mounts)


Batch = RangeBatch | PoseBatch | MountBatch


@dataclass(frozen=True)
class TopicInfo:
    """One topic (or CSV file/stream) of a log, as ``ros2 bag info`` lists it."""

    name: str
    msgtype: str
    count: int
    encoding: str = ""  # 'ros1', 'cdr', 'csv', ...
    role: str = ""  # what sonarmap uses it for: 'range', 'pose', 'tf', 'tf_static', 'laser', ''


@dataclass(frozen=True)
class LogFile:
    """One file of a recording read from several files: path, log-time span, messages."""

    path: str
    start_ns: int | None
    end_ns: int | None
    message_count: int


@dataclass
class LogInfo:
    """What a log holds: format, time span and topics, plus what sonarmap found in it."""

    path: str
    format: str
    start_ns: int | None
    end_ns: int | None
    message_count: int
    topics: list[TopicInfo]
    range_topics: list[str] = field(default_factory=list)
    pose_topic: str | None = None
    notes: list[str] = field(default_factory=list)
    # What could not be read of a damaged log (truncated, cut by power loss, corrupt
    # chunks): one line per loss, and the bytes lost; the rest is read and mapped.
    losses: list[str] = field(default_factory=list)
    bytes_lost: int = 0
    # A recording read from several files (split bags, sonar and odometry bags): each
    # file in time order; empty for a log in one file (or one bag directory).
    files: list[LogFile] = field(default_factory=list)
    # Of those: messages found in two files (same topic, log time and bytes), read once.
    duplicates_read_once: int = 0

    @property
    def duration_s(self) -> float:
        if self.start_ns is None or self.end_ns is None:
            return 0.0
        return (self.end_ns - self.start_ns) / 1e9


@runtime_checkable
class LogReader(Protocol):
    """What every reader implements (ROS 1 bag, ROS 2 bag, MCAP, CSV).

    ``batches`` streams the log in bounded memory (chunk by chunk), in log order, yielding
    only the kinds asked for; it may be called more than once (the pipeline reads poses
    and mounts in a first pass and ranges in a second). ``sensor_names`` grows as new
    sensors are met; ``sensor_id`` values index it.
    """

    path: Location
    format_name: str
    sensor_names: list[str]

    def info(self) -> LogInfo: ...

    def batches(self, kinds: Sequence[Kind] = ALL_KINDS) -> Iterator[Batch]: ...

    def close(self) -> None: ...

    def __enter__(self) -> LogReader: ...

    def __exit__(self, *exc: object) -> None: ...
