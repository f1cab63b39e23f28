"""Test helper: one recording cut into several files, as recorders write them.

``split_mcap``/``split_ros1`` copy every message of a log (same log time, same bytes,
same schema/definition) into the first of the given parts whose predicate accepts
``(topic, log_time_ns, data)``: by time (``rosbag record --split``), by topic (sonar and
odometry bags), or by anything else.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

Accept = Callable[[str, int, bytes], bool]


def split_mcap(src: Path, parts: Sequence[tuple[Path, Accept]], *, shift_ns: int = 0,
               chunk_size: int = 1024 * 1024) -> None:
    """Copy ``src``'s messages into MCAP files (log and publish times + ``shift_ns``)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    outs: list[tuple[Any, Any, Accept, dict[int, int], dict[int, int]]] = []
    for path, accept in parts:
        f = path.open("wb")
        w = Writer(f, chunk_size=chunk_size)
        w.start(profile="ros2", library="sonarmap tests")
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

    writers = [Writer(path) for path, _ in parts]
    conns: list[dict[int, Any]] = [{} for _ in parts]
    for w in writers:
        w.open()
    try:
        with Reader(src) as reader:
            for conn, t, data in reader.messages():
                for k, (_, accept) in enumerate(parts):
                    if not accept(conn.topic, t, data):
                        continue
                    if conn.id not in conns[k]:
                        ext = conn.ext
                        conns[k][conn.id] = writers[k].add_connection(
                            conn.topic, conn.msgtype, msgdef=conn.msgdef.data,
                            md5sum=conn.digest, callerid=ext.callerid, latching=ext.latching)
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


def split_ros2(src: Path, parts: Sequence[tuple[Path, Accept]]) -> None:
    """Copy ``src``'s messages into rosbag2 directories (sqlite3, same definitions)."""
    from rosbags.rosbag2 import Reader, Writer

    writers = [Writer(path, version=9) for path, _ in parts]
    conns: list[dict[int, Any]] = [{} for _ in parts]
    for w in writers:
        w.open()
    try:
        with Reader(src) as reader:
            for conn, t, data in reader.messages():
                for k, (_, accept) in enumerate(parts):
                    if not accept(conn.topic, t, data):
                        continue
                    if conn.id not in conns[k]:
                        conns[k][conn.id] = writers[k].add_connection(
                            conn.topic, conn.msgtype, msgdef=conn.msgdef.data,
                            rihs01=conn.digest,
                            offered_qos_profiles=conn.ext.offered_qos_profiles)
                    writers[k].write(conns[k][conn.id], t, data)
                    break
    finally:
        for w in writers:
            w.close()
