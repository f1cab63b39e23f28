"""ROS semantics on top of a message container: topics → the reader contract.

:class:`RosLogReader` works on any :class:`~formats.ros.source.MessageSource` (ROS 1 bag,
ROS 2 bag, MCAP) and only through that interface and :func:`formats.ros.decode.decode`.
It chooses the topics (by type, or as configured), turns decoded columns into
:class:`RangeBatch` / :class:`PoseBatch` / :class:`MountBatch` and reads poses and sensor
mounts from tf when the log has no odometry topic.

Range sources: ``sensor_msgs/Range`` (one reading per message, sensor = ``frame_id``),
RosAria's ``sensor_msgs/PointCloud`` sonar (one point per sonar of the ring, in the robot
frame) and ``p2os_msgs/SonarArray`` (``ranges[i]`` = sonar i). The last two carry no
sensor geometry: their mounts and beam limits come from the configuration.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from formats.contract import (
    ALL_KINDS,
    Batch,
    Kind,
    LogInfo,
    MountBatch,
    PoseBatch,
    RangeBatch,
    SensorMount,
    TopicInfo,
    make_range_batch,
)
from formats.errors import ConfigError, FormatError, TopicError
from formats.options import ReaderOptions, ReaderSettings
from formats.ros import tf as tflib
from formats.ros.columns import (
    LASER_TYPES,
    POINTCLOUD_TYPES,
    POSE_TYPES,
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
from formats.ros.decode import decode
from formats.ros.decode_messages import MessageError
from formats.ros.source import Connection, MessageSource, RawBatch, messages_lost
from formats.sensor_config import SensorRing, sensor_setup

RING_TYPES = POINTCLOUD_TYPES | SONARARRAY_TYPES
# Messages of one batch that may fail to decode one by one (each decode retried without
# it); past this the rest of the batch is lost too (damage that wide is not one message).
MAX_BAD_MESSAGES = 32
RANGE_SOURCE_TYPES = RANGE_TYPES | RING_TYPES
ODOMETRY = "nav_msgs/msg/Odometry"


def _short(msgtype: str) -> str:
    return msgtype.rsplit("/", 1)[-1]


def _is_static_tf(topic: str) -> bool:
    return topic.rstrip("/").endswith("tf_static")


@dataclass
class _Selection:
    """Topics chosen for ranges and poses; errors kept until those kinds are asked for."""

    range_topics: list[str] = field(default_factory=list)
    pose_topics: list[str] = field(default_factory=list)  # tf: every non-static tf topic
    pose_is_tf: bool = False
    range_error: TopicError | None = None
    pose_error: TopicError | None = None

    @property
    def pose_topic(self) -> str | None:
        return self.pose_topics[0] if self.pose_topics else None


@dataclass
class _PassState:
    """What one streaming pass carries from chunk to chunk."""

    scan_counter: int = 0
    last_values: dict[str, npt.NDArray[np.float64]] = field(default_factory=dict)
    # The Range messages' frame ids in order of their first reading (the mounts' frames).
    range_frames: dict[str, None] = field(default_factory=dict)


class RosLogReader:
    """The :class:`~formats.contract.LogReader` of ROS logs (any MessageSource)."""

    def __init__(self, source: MessageSource, config: ReaderSettings | None = None) -> None:
        self.source = source
        self.config = config if config is not None else ReaderOptions()
        self.path = source.path
        self.format_name = source.format_name
        self.sensor_names: list[str] = []
        self._sensor_ids: dict[str, int] = {}
        self._connections = source.connections
        self._topics: dict[str, list[Connection]] = {}
        for c in self._connections:
            self._topics.setdefault(c.topic, []).append(c)
        self._selection = self._select()
        self._links: dict[str, tflib.Link] | None = None
        self._range_frames: list[str] | None = None
        # (topic, log time ns) → why: messages skipped because they do not decode.
        self._undecodable: dict[tuple[str, int], str] = {}

    # ------------------------------------------------------------------ contract

    def __enter__(self) -> RosLogReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the underlying source."""
        self.source.close()

    @property
    def range_topics(self) -> list[str]:
        """Topics read for ranges (empty when the log has none)."""
        return list(self._selection.range_topics)

    @property
    def pose_topic(self) -> str | None:
        """Topic read for poses (the tf topic for a tf chain), None when there is none."""
        return self._selection.pose_topic

    def info(self) -> LogInfo:
        """What the log holds: topics with counts from the index, chosen topics, notes."""
        sel = self._selection
        topics = [
            TopicInfo(
                name=name,
                msgtype=conns[0].msgtype,
                count=sum(c.count for c in conns),
                encoding=conns[0].encoding,
                role=self._role(name, conns[0].msgtype),
            )
            for name, conns in self._topics.items()
        ]
        notes = list(self.source.warnings)
        for err in (sel.range_error, sel.pose_error):
            if err is not None:
                notes.append(err.reason)
        if sel.pose_is_tf:
            notes.append(
                f"poses from the tf chain to {self.config.input.base_frame} "
                f"({', '.join(sel.pose_topics)})"
            )
        notes += self._range_notes()
        notes += [w for w in [*self.source.warnings, *self._undecodable_lines()]
                  if w not in notes]
        notes += getattr(self.source, "notes", [])  # several files: duplicates read once
        name = self.path.name
        several = bool(getattr(self.source, "files", None))  # its lines name their files
        return LogInfo(
            path=str(self.path),
            format=self.format_name,
            start_ns=self.source.start_ns,
            end_ns=self.source.end_ns,
            message_count=max(0, sum(t.count for t in topics) - messages_lost(self.source)
                              - len(self._undecodable)),
            topics=topics,
            range_topics=list(sel.range_topics),
            pose_topic=sel.pose_topic,
            notes=notes,
            # Each loss names its file (a source's own lines may name only the place).
            losses=[w if name in w or several else f"{name}: {w}"
                    for w in [*self.source.warnings, *self._undecodable_lines()]],
            bytes_lost=self.source.bytes_lost,
            files=list(getattr(self.source, "files", [])),
            duplicates_read_once=getattr(self.source, "duplicates_read_once", 0),
        )

    def batches(self, kinds: Sequence[Kind] = ALL_KINDS) -> Iterator[Batch]:
        """Stream the asked kinds: the MountBatch, then (tf) poses, then range and pose
        batches chunk by chunk in log order. With ranges asked too, the MountBatch comes
        last instead: the Range frames it needs are learnt from the stream itself, so the
        log is not read twice.

        Raises :class:`TopicError` when ranges/poses are asked for and the log has no (or
        an ambiguous) source of them, :class:`ConfigError` when a PointCloud/SonarArray
        ring has no mounts configured.
        """
        want = set(kinds)
        sel = self._selection
        if "ranges" in want and sel.range_error is not None:
            raise TopicError(sel.range_error.reason, self.path)
        if "poses" in want and sel.pose_error is not None:
            raise TopicError(sel.pose_error.reason, self.path)
        rings: dict[str, SensorRing] = {}
        if "ranges" in want:
            for topic in sel.range_topics:
                msgtype = self._topics[topic][0].msgtype
                if msgtype in RING_TYPES:
                    rings[topic] = self._ring(topic, msgtype)
        ids: list[int] = []
        if "ranges" in want:
            ids += [c.id for t in sel.range_topics for c in self._topics[t]]
        if "poses" in want and not sel.pose_is_tf:
            ids += [c.id for t in sel.pose_topics for c in self._topics[t]]
        mounts_last = "mounts" in want and "ranges" in want and bool(ids)
        if "mounts" in want and not mounts_last:
            yield self._mounts()
        if "poses" in want and sel.pose_is_tf:
            yield self._tf_poses()
        if not ids:
            return
        state = _PassState()
        group: list[RawBatch] = []
        for raw in self.source.raw_batches(ids):
            # Batches of one chunk share its buffer: merge them into log order together.
            if group and raw.buffer is not group[0].buffer:
                yield from self._convert_group(group, rings, state)
                group = []
            group.append(raw)
        if group:
            yield from self._convert_group(group, rings, state)
        if mounts_last:
            if self._range_frames is None:
                self._range_frames = list(state.range_frames)
            yield self._mounts()

    # ------------------------------------------------------------------ laser scans

    def laser_topic(self, requested: str | None = None) -> str:
        """The sensor_msgs/LaserScan topic: ``requested``, else the log's only one."""
        conns = self._connections
        lasers = sorted({c.topic for c in conns if c.msgtype in LASER_TYPES})
        listing = ", ".join(sorted({f"{c.topic}:{c.msgtype}" for c in conns})) or "nothing"
        if requested:
            if requested not in lasers:
                raise TopicError(
                    f"laser topic {requested} is not a sensor_msgs/LaserScan topic of the "
                    f"log; the log contains: {listing}",
                    self.path,
                )
            return requested
        if len(lasers) == 1:
            return lasers[0]
        if not lasers:
            raise TopicError(
                f"no sensor_msgs/LaserScan topic; the log contains: {listing}", self.path
            )
        raise TopicError(
            f"several LaserScan topics ({', '.join(lasers)}): choose one with --laser-topic",
            self.path,
        )

    def laser_columns(self, topic: str, max_scans: int | None = None) -> list[LaserScanColumns]:
        """The decoded messages of a LaserScan topic, in log order; reading stops once
        ``max_scans`` messages are in."""
        parts: list[LaserScanColumns] = []
        count = 0
        gen = self.source.raw_batches([c.id for c in self._topics.get(topic, [])])
        try:
            for raw in gen:
                raw, cols = self._decode(raw)
                assert isinstance(cols, LaserScanColumns)
                parts.append(cols)
                count += cols.stamp_ns.shape[0]
                if max_scans is not None and count >= max_scans:
                    break
        finally:
            close = getattr(gen, "close", None)
            if close is not None:
                close()
        return parts

    def static_mount(self, frame: str) -> SensorMount | None:
        """The static transform base frame → ``frame`` from tf, None when there is none."""
        self._prepass(need_frames=False)
        assert self._links is not None
        return tflib.static_mount(self._links, self.config.input.base_frame, frame.lstrip("/"))

    # ------------------------------------------------------------------ selection

    def _contents(self) -> str:
        if not self._topics:
            return "the log contains no topics"
        listing = ", ".join(f"{t}:{c[0].msgtype}" for t, c in self._topics.items())
        return f"the log contains: {listing}"

    def _select(self) -> _Selection:
        sel = _Selection()
        inp = self.config.input
        types = {t: c[0].msgtype for t, c in self._topics.items()}
        if inp.range_topics:
            for t in inp.range_topics:
                if t not in types:
                    sel.range_error = TopicError(
                        f"range topic {t} is not in the log; {self._contents()}", self.path
                    )
                    break
                if types[t] not in RANGE_SOURCE_TYPES:
                    sel.range_error = TopicError(
                        f"range topic {t} is {types[t]}, not sensor_msgs/Range, PointCloud "
                        f"or p2os_msgs/SonarArray; {self._contents()}",
                        self.path,
                    )
                    break
                sel.range_topics.append(t)
        else:
            sel.range_topics = [t for t, m in types.items() if m in RANGE_SOURCE_TYPES]
            if not sel.range_topics:
                sel.range_error = TopicError(
                    "no range topic (sensor_msgs/Range, sensor_msgs/PointCloud or "
                    f"p2os_msgs/SonarArray); {self._contents()}",
                    self.path,
                )
        if sel.range_error is not None:
            sel.range_topics = []

        tf_topics = [t for t, m in types.items() if m in TF_TYPES and not _is_static_tf(t)]
        if inp.pose_topic:
            t = inp.pose_topic
            if t not in types:
                sel.pose_error = TopicError(
                    f"pose topic {t} is not in the log; {self._contents()}", self.path
                )
            elif types[t] in TF_TYPES:
                sel.pose_topics, sel.pose_is_tf = [t], True
            elif types[t] in POSE_TYPES:
                sel.pose_topics = [t]
            else:
                sel.pose_error = TopicError(
                    f"pose topic {t} is {types[t]}, not Odometry, PoseStamped, "
                    f"PoseWithCovarianceStamped or tf; {self._contents()}",
                    self.path,
                )
            return sel
        odom = [t for t, m in types.items() if m == ODOMETRY]
        stamped = [t for t, m in types.items() if m in POSE_TYPES and m != ODOMETRY]
        for found, what in ((odom, "odometry"), (stamped, "pose")):
            if len(found) == 1:
                sel.pose_topics = found
                return sel
            if len(found) > 1:
                sel.pose_error = TopicError(
                    f"several {what} topics ({', '.join(found)}): choose one with "
                    f"input.pose_topic; {self._contents()}",
                    self.path,
                )
                return sel
        if tf_topics:
            sel.pose_topics, sel.pose_is_tf = tf_topics, True
            return sel
        sel.pose_error = TopicError(
            "no pose source (nav_msgs/Odometry, PoseStamped, PoseWithCovarianceStamped "
            f"or tf); {self._contents()}",
            self.path,
        )
        return sel

    def _role(self, topic: str, msgtype: str) -> str:
        sel = self._selection
        if topic in sel.range_topics:
            return "range"
        if msgtype in TF_TYPES:
            return "tf_static" if _is_static_tf(topic) else "tf"
        if topic in sel.pose_topics:
            return "pose"
        if msgtype in LASER_TYPES:
            return "laser"
        return ""

    # ------------------------------------------------------------------ helpers

    def _decode(self, raw: RawBatch) -> tuple[RawBatch, Columns]:
        """The batch decoded (and the batch its columns are of), naming the file in errors
        the decoder raises without it. A message that does not decode is skipped and
        recorded (:meth:`_undecodable_lines`): the batch returned is without it; past
        MAX_BAD_MESSAGES in one batch, the rest of the batch is lost with them."""
        for _ in range(MAX_BAD_MESSAGES):
            try:
                return raw, decode(raw)
            except MessageError as err:
                self._undecodable.setdefault(
                    (raw.connection.topic, int(raw.log_time_ns[err.index])), err.reason)
                keep = np.ones(len(raw), bool)
                keep[err.index] = False
                raw = RawBatch(raw.connection, raw.log_time_ns[keep], raw.buffer,
                               raw.offsets[keep], raw.lengths[keep])
            except FormatError as err:
                if err.path is None:
                    raise FormatError(err.reason, self.path) from err
                raise
        for t in raw.log_time_ns.tolist():
            self._undecodable.setdefault((raw.connection.topic, int(t)),
                                         "in a batch of too many that do not decode")
        empty = RawBatch(raw.connection, raw.log_time_ns[:0], raw.buffer, raw.offsets[:0],
                         raw.lengths[:0])
        return empty, decode(empty)

    def _undecodable_lines(self) -> list[str]:
        """One loss line per topic whose messages did not decode."""
        first: dict[str, tuple[int, str]] = {}
        for (topic, _t), reason in self._undecodable.items():
            n, why = first.get(topic, (0, reason))
            first[topic] = (n + 1, why)
        return [f"{topic}: {n} messages do not decode and are lost (first: {why})"
                for topic, (n, why) in sorted(first.items())]

    def _sensor_id(self, name: str) -> int:
        sid = self._sensor_ids.get(name)
        if sid is None:
            sid = self._sensor_ids[name] = len(self.sensor_names)
            self.sensor_names.append(name)
        return sid

    def _ring(self, topic: str, msgtype: str) -> SensorRing:
        """Mount geometry of a PointCloud/SonarArray ring (see :mod:`formats.sensor_config`)."""
        ring = sensor_setup(self.config.sensors).ring()
        if ring is None:
            raise ConfigError(
                f"topic {topic} is {msgtype}, which carries no sensor geometry: set "
                "sensors.preset (e.g. 'pioneer-p3dx') or [[sensors.mounts]] (in ring order)",
                self.path,
            )
        return ring

    # ------------------------------------------------------------------ streaming

    def _convert_group(
        self, group: list[RawBatch], rings: dict[str, SensorRing], state: _PassState
    ) -> Iterator[Batch]:
        ranges: list[RangeBatch] = []
        poses: dict[tuple[str, str], list[PoseBatch]] = {}
        for raw in group:
            raw, cols = self._decode(raw)
            topic = raw.connection.topic
            if isinstance(cols, RangeColumns):
                ranges.append(self._range_batch(raw, cols, state))
            elif isinstance(cols, PointColumns):
                ranges.append(self._pointcloud_batch(raw, cols, rings[topic], state))
            elif isinstance(cols, SonarArrayColumns):
                ranges.append(self._sonararray_batch(raw, cols, rings[topic], state))
            elif isinstance(cols, PoseColumns):
                for pb in self._pose_batches(raw, cols):
                    poses.setdefault((pb.parent_frame, pb.child_frame), []).append(pb)
        for (parent, child), parts in poses.items():
            yield _merge_poses(parts, parent, child)
        if ranges:
            merged = RangeBatch.concat(ranges)
            if len(ranges) > 1:
                merged = merged.take(np.argsort(merged.record_t_ns, kind="stable"))
            if len(merged):
                yield merged

    def _range_batch(self, raw: RawBatch, cols: RangeColumns, state: _PassState) -> RangeBatch:
        present = np.unique(cols.frame)
        # New sensors get ids in order of their first reading (stable, readable ids).
        for code in present[np.argsort(_first_index(cols.frame, present))]:
            frame = cols.frames[int(code)]
            self._sensor_id(frame)
            state.range_frames.setdefault(frame, None)
        lut = np.array([self._sensor_id(f) for f in cols.frames], np.int32)
        return make_range_batch(
            cols.stamp_ns,
            lut[cols.frame] if lut.size else np.zeros(0, np.int32),
            cols.range,
            cols.field_of_view,
            cols.min_range,
            cols.max_range,
            record_t_ns=raw.log_time_ns,
            variance=cols.variance,
        )

    def _ring_batch(
        self,
        raw: RawBatch,
        ring: SensorRing,
        msg_index: npt.NDArray[np.int64],
        sonar: npt.NDArray[np.int64],
        stamp: npt.NDArray[np.int64],
        range_m: npt.NDArray[np.float64],
        state: _PassState,
    ) -> RangeBatch:
        if sonar.size and int(sonar.max()) >= len(ring.names):
            raise ConfigError(
                f"topic {raw.connection.topic} has {int(sonar.max()) + 1} sonars per "
                f"message but {ring.origin} has {len(ring.names)} mounts",
                self.path,
            )
        lut = np.array([self._sensor_id(n) for n in ring.names], np.int32)
        return make_range_batch(
            stamp,
            lut[sonar],
            range_m,
            ring.fov[sonar],
            ring.min_range[sonar],
            ring.max_range[sonar],
            # One message carries a whole ring: it is one scan.
            scan_id=state.scan_counter + msg_index,
            record_t_ns=raw.log_time_ns[msg_index],
        )

    def _pointcloud_batch(
        self, raw: RawBatch, cols: PointColumns, ring: SensorRing, state: _PassState
    ) -> RangeBatch:
        """Point i of a message is sonar i; range = distance from its mount to the point."""
        per = cols.points_per_message
        sonar = np.arange(cols.msg_index.shape[0], dtype=np.int64) - np.repeat(
            np.cumsum(per) - per, per
        )
        if sonar.size and int(sonar.max()) >= len(ring.names):
            raise ConfigError(
                f"topic {raw.connection.topic} has {int(sonar.max()) + 1} points per "
                f"message but {ring.origin} has {len(ring.names)} mounts",
                self.path,
            )
        rng = np.hypot(cols.x - ring.x[sonar], cols.y - ring.y[sonar])
        batch = self._ring_batch(raw, ring, cols.msg_index, sonar, cols.stamp_ns, rng, state)
        state.scan_counter += len(raw)
        return batch

    def _sonararray_batch(
        self, raw: RawBatch, cols: SonarArrayColumns, ring: SensorRing, state: _PassState
    ) -> RangeBatch:
        """ranges[i] is sonar i; a value equal to the previous value of the same sonar is
        a republished stale reading (p2os), not a new measurement: dropped."""
        idx, val = cols.index, cols.value
        size = max(int(idx.max()) + 1 if idx.size else 0, len(ring.names))
        last = state.last_values.get(raw.connection.topic)
        if last is None or last.shape[0] < size:
            grown = np.full(size, np.nan)
            if last is not None:
                grown[: last.shape[0]] = last
            last = grown
        order = np.lexsort((cols.msg_index, idx))  # by sonar, then message
        s_idx, s_val = idx[order], val[order]
        first = np.r_[True, s_idx[1:] != s_idx[:-1]] if s_idx.size else np.zeros(0, bool)
        prev = np.empty_like(s_val)
        prev[1:] = s_val[:-1]
        prev[first] = last[s_idx[first]]
        keep_sorted = s_val != prev  # NaN never equals: erroneous readings are kept
        final = np.r_[s_idx[1:] != s_idx[:-1], True] if s_idx.size else np.zeros(0, bool)
        last[s_idx[final]] = s_val[final]
        state.last_values[raw.connection.topic] = last
        keep = np.zeros(idx.shape[0], bool)
        keep[order] = keep_sorted
        batch = self._ring_batch(
            raw, ring, cols.msg_index[keep], idx[keep], cols.stamp_ns[keep], val[keep], state
        )
        state.scan_counter += len(raw)
        return batch

    def _pose_batches(self, raw: RawBatch, cols: PoseColumns) -> list[PoseBatch]:
        base = self.config.input.base_frame
        yaw = tflib.yaw_from_quaternion(cols.qx, cols.qy, cols.qz, cols.qw)
        out = []
        key = cols.frame.astype(np.int64) * (len(cols.frames) + 1) + cols.child
        for k in np.unique(key):  # one (parent, child) pair per topic in practice
            m = key == k
            p, c = divmod(int(k), len(cols.frames) + 1)
            child = cols.frames[c] or base
            out.append(
                PoseBatch(
                    cols.stamp_ns[m],
                    cols.x[m],
                    cols.y[m],
                    yaw[m],
                    parent_frame=cols.frames[p],
                    child_frame=child,
                    record_t_ns=raw.log_time_ns[m],
                )
            )
        return out

    # ------------------------------------------------------------------ tf

    def _prepass(self, need_frames: bool) -> None:
        """Read tf (and, for mounts, the Range frame ids) once; cached."""
        need_links = self._links is None
        need_frames = need_frames and self._range_frames is None
        if not (need_links or need_frames):
            return
        ids: list[int] = []
        if need_links:
            ids += [c.id for c in self._connections if c.msgtype in TF_TYPES]
        range_topics = [
            t for t in self._selection.range_topics if self._topics[t][0].msgtype in RANGE_TYPES
        ]
        if need_frames:
            ids += [c.id for t in range_topics for c in self._topics[t]]
        tables: list[tuple[TransformColumns, bool]] = []
        frames: dict[str, None] = {}
        for raw in self.source.raw_batches(ids):
            raw, cols = self._decode(raw)
            if isinstance(cols, TransformColumns):
                tables.append((cols, _is_static_tf(raw.connection.topic)))
            elif isinstance(cols, RangeColumns):
                present = np.unique(cols.frame)
                for code in present[np.argsort(_first_index(cols.frame, present))]:
                    frames.setdefault(cols.frames[int(code)], None)
        if need_links:
            self._links = tflib.build_links(tables)
        if need_frames:
            self._range_frames = list(frames)

    def _mounts(self) -> MountBatch:
        """Static mounts of the Range sensor frames in the base frame, from tf."""
        self._prepass(need_frames=True)
        assert self._links is not None and self._range_frames is not None
        base = self.config.input.base_frame
        mounts = {}
        for frame in self._range_frames:
            m = tflib.static_mount(self._links, base, frame.lstrip("/"))
            if m is not None:
                mounts[frame] = m
        return MountBatch(base, mounts)

    def _tf_poses(self) -> PoseBatch:
        self._prepass(need_frames=False)
        assert self._links is not None
        base = self.config.input.base_frame
        if base not in self._links:
            known = sorted({f for lk in self._links.values() for f in (lk.parent, lk.child)})
            raise TopicError(
                f"tf has no transform to the base frame '{base}' (input.base_frame); "
                f"frames in tf: {', '.join(known) or 'none'}",
                self.path,
            )
        return tflib.pose_batch(self._links, base)

    # ------------------------------------------------------------------ info

    def _range_notes(self) -> list[str]:
        """One note per range topic from its first chunk: sensors, beam width, limits."""
        notes: list[str] = []
        sel = self._selection
        topics = [t for t in sel.range_topics if self._topics[t][0].msgtype in RANGE_TYPES]
        firsts: dict[str, RangeColumns] = {}
        if topics:
            ids = [c.id for t in topics for c in self._topics[t]]
            gen = self.source.raw_batches(ids)
            try:
                for raw in gen:
                    if raw.connection.topic in firsts:
                        continue
                    raw, cols = self._decode(raw)
                    if isinstance(cols, RangeColumns) and len(cols.stamp_ns):
                        firsts[raw.connection.topic] = cols
                    if len(firsts) == len(topics):
                        break
            finally:
                close = getattr(gen, "close", None)
                if close is not None:
                    close()
        for t in sel.range_topics:
            msgtype = self._topics[t][0].msgtype
            if msgtype in RING_TYPES:
                try:
                    ring = self._ring(t, msgtype)
                    notes.append(
                        f"{t}: {_short(msgtype)} sonar ring, {len(ring.names)} mounts from "
                        f"{ring.origin}"
                    )
                except ConfigError as err:
                    notes.append(err.reason)
                continue
            rc = firsts.get(t)
            if rc is None:
                continue
            present = np.unique(rc.frame)
            first = _first_index(rc.frame, present)
            parts = []
            for code, i in sorted(
                zip(present.tolist(), first.tolist(), strict=True), key=lambda p: p[1]
            ):
                parts.append(
                    f"{rc.frames[code]} fov {rc.field_of_view[i]:.2f} rad "
                    f"{rc.min_range[i]:.2f}-{rc.max_range[i]:.2f} m"
                )
            notes.append(f"{t}: {len(parts)} range sensors: {', '.join(parts)}")
        return notes


def _first_index(
    codes: npt.NDArray[np.int32], present: npt.NDArray[np.int32]
) -> npt.NDArray[np.intp]:
    """Index of the first occurrence of each value of ``present`` in ``codes``."""
    return np.array([int(np.argmax(codes == c)) for c in present], np.intp)


def _merge_poses(parts: list[PoseBatch], parent: str, child: str) -> PoseBatch:
    if len(parts) == 1:
        return parts[0]
    rec = np.concatenate([p.record_t_ns for p in parts if p.record_t_ns is not None])
    order = np.argsort(rec, kind="stable")
    return PoseBatch(
        np.concatenate([p.t_ns for p in parts])[order],
        np.concatenate([p.x for p in parts])[order],
        np.concatenate([p.y for p in parts])[order],
        np.concatenate([p.yaw for p in parts])[order],
        parent_frame=parent,
        child_frame=child,
        record_t_ns=rec[order],
    )
