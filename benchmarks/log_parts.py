"""One recording cut into several files, as recorders write them (tests and benchmarks).

``split_mcap``/``split_ros1``/``split_ros2`` copy every message of a log (same log time,
same bytes, same schema/definition) into the first of the given parts whose predicate
accepts ``(topic, log_time_ns, data)``: by time (``rosbag record --split``), by topic
(sonar and odometry bags), or by anything else. A message no part accepts is left out.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

Accept = Callable[[str, int, bytes], bool]


def split_mcap(src: Path, parts: Sequence[tuple[Path, Accept]], *, shift_ns: int = 0,
               chunk_size: int = 1024 * 1024, compression: str = "zstd") -> None:
    """Copy ``src``'s messages into MCAP files (log and publish times + ``shift_ns``;
    ``compression``: ``zstd`` chunks, as mcap's writer defaults to, ``lz4`` or ``none``)."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    outs: list[tuple[Any, Any, Accept, dict[int, int], dict[int, int]]] = []
    for path, accept in parts:
        f = path.open("wb")
        w = Writer(f, chunk_size=chunk_size, compression=CompressionType[compression.upper()])
        w.start(profile="ros2", library="sonarmap log_parts")
        outs.append((f, w, accept, {}, {}))
    with src.open("rb") as fin:
        for schema, channel, msg in make_reader(fin).iter_messages(log_time_order=False):
            for _, w, accept, schemas, channels in outs:
                if not accept(channel.topic, msg.log_time, msg.data):
                    continue
                if schema.id not in schemas:
                    schemas[schema.id] = w.register_schema(schema.name, schema.encoding,
                                                           schema.data)
                if channel.id not in channels:
                    channels[channel.id] = w.register_channel(
                        channel.topic, channel.message_encoding, schemas[schema.id],
                        channel.metadata)
                w.add_message(channels[channel.id], msg.log_time + shift_ns, msg.data,
                              msg.publish_time + shift_ns, msg.sequence)
                break
    for f, w, *_ in outs:
        w.finish()
        f.close()


def split_ros1(src: Path, parts: Sequence[tuple[Path, Accept]]) -> None:
    """Copy ``src``'s messages into ROS 1 bags (same definitions, md5sums, callerids)."""
    from rosbags.rosbag1 import Reader, Writer

    def connection(w: Any, conn: Any) -> Any:
        return w.add_connection(conn.topic, conn.msgtype, msgdef=conn.msgdef.data,
                                md5sum=conn.digest, callerid=conn.ext.callerid,
                                latching=conn.ext.latching)

    _split_rosbags(Reader(src), [Writer(path) for path, _ in parts], parts, connection)


def split_ros2(src: Path, parts: Sequence[tuple[Path, Accept]]) -> None:
    """Copy ``src``'s messages into rosbag2 directories (sqlite3, same definitions)."""
    from rosbags.rosbag2 import Reader, Writer

    def connection(w: Any, conn: Any) -> Any:
        return w.add_connection(conn.topic, conn.msgtype, msgdef=conn.msgdef.data,
                                rihs01=conn.digest,
                                offered_qos_profiles=conn.ext.offered_qos_profiles)

    _split_rosbags(Reader(src), [Writer(path, version=9) for path, _ in parts], parts,
                   connection)


def _split_rosbags(reader: Any, writers: list[Any], parts: Sequence[tuple[Path, Accept]],
                   connection: Callable[[Any, Any], Any]) -> None:
    """The copy loop of :func:`split_ros1`/:func:`split_ros2` (rosbags readers and writers;
    ``connection`` adds a reader connection to a writer)."""
    conns: list[dict[int, Any]] = [{} for _ in parts]
    for w in writers:
        w.open()
    try:
        with reader:
            for conn, t, data in reader.messages():
                for k, (_, accept) in enumerate(parts):
                    if not accept(conn.topic, t, data):
                        continue
                    if conn.id not in conns[k]:
                        conns[k][conn.id] = connection(writers[k], conn)
                    writers[k].write(conns[k][conn.id], t, data)
                    break
    finally:
        for w in writers:
            w.close()


def before(t_split_ns: int) -> Accept:
    return lambda topic, t, data: t < t_split_ns


def anything() -> Accept:
    return lambda topic, t, data: True


def topics(*names: str) -> Accept:
    return lambda topic, t, data: topic in names
