"""Several files of one recording read as one source (formats/ros/multi_source.py) and
opened through the one format route (formats.open_log)."""

from __future__ import annotations

import itertools
import shutil
from collections.abc import Collection, Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.log_parts import anything, before, split_mcap, topics
from formats import open_log
from formats.contract import PoseBatch, RangeBatch
from formats.errors import FormatError
from formats.ros.multi_source import MERGE_SLACK_NS, MultiSource
from formats.ros.source import Connection, RawBatch

ROOT = Path(__file__).resolve().parents[3]
OFFICE = ROOT / "sample_logs" / "office" / "office.mcap"
T0 = 1_700_000_000_000_000_000
S = 1_000_000_000


class FakeSource:
    """A MessageSource of given messages: ``{topic: [(log_time_ns, bytes), ...]}``, one
    batch per topic and ``batch_s`` of log time (as a chunked file gives them)."""

    def __init__(self, path: str, messages: dict[str, list[tuple[int, bytes]]], *,
                 msgtypes: dict[str, str] | None = None, format_name: str = "mcap",
                 batch_s: float = 2.0, warnings: list[str] | None = None,
                 bytes_lost: int = 0) -> None:
        self.path = Path(path)
        self.format_name = format_name
        types = msgtypes or {}
        self.connections = [
            Connection(i, t, types.get(t, "sensor_msgs/msg/Range"), "cdr", "", "", len(m))
            for i, (t, m) in enumerate(messages.items())
        ]
        self._messages = messages
        stamps = [t for m in messages.values() for t, _ in m]
        self.start_ns = min(stamps) if stamps else None
        self.end_ns = max(stamps) if stamps else None
        self._batch_ns = int(batch_s * S)
        self.warnings = warnings or []
        self.bytes_lost = bytes_lost
        self.closed = False

    def raw_batches(self, connection_ids: Collection[int]) -> Iterator[RawBatch]:
        """Chunk by chunk (``batch_s`` of log time), one batch per topic, the batches of a
        chunk sharing one buffer (as the real sources give them)."""
        if self.start_ns is None:
            return
        chunks: dict[int, dict[int, list[tuple[int, bytes]]]] = {}
        for c in self.connections:
            if c.id not in connection_ids:
                continue
            for t, data in self._messages[c.topic]:
                k = (t - self.start_ns) // self._batch_ns
                chunks.setdefault(k, {}).setdefault(c.id, []).append((t, data))
        for k in sorted(chunks):
            parts = chunks[k]
            buffer = np.frombuffer(b"".join(d for m in parts.values() for _, d in m), np.uint8)
            at = 0
            for cid, msgs in parts.items():
                lengths = np.array([len(d) for _, d in msgs], np.int64)
                yield RawBatch(self.connections[cid], np.array([t for t, _ in msgs], np.int64),
                               buffer, at + np.cumsum(lengths) - lengths, lengths)
                at += int(lengths.sum())

    def close(self) -> None:
        self.closed = True


def stream(topic: str, t0_s: float, t1_s: float, hz: float, tag: bytes) -> list[tuple[int, bytes]]:
    n = round((t1_s - t0_s) * hz)
    return [(T0 + int((t0_s + i / hz) * S), tag + str(i).encode()) for i in range(n)]


def as_the_reader_sees_it(pieces: list[RawBatch]) -> np.ndarray:
    """Log times in the order the ROS reader hands them on: consecutive batches of one
    buffer (one chunk) merged and sorted by log time together."""
    out: list[np.ndarray] = []
    group: list[RawBatch] = []
    for p in [*pieces, None]:
        if group and (p is None or p.buffer is not group[0].buffer):
            out.append(np.sort(np.concatenate([g.log_time_ns for g in group]), kind="stable"))
            group = []
        if p is not None:
            group.append(p)
    return np.concatenate(out)


def lateness(times: np.ndarray) -> int:
    """How far the stream ever goes back in time, ns."""
    return int((np.maximum.accumulate(times) - times).max())


def read_all(src: MultiSource) -> list[tuple[str, int, bytes]]:
    pieces = list(src.raw_batches([c.id for c in src.connections]))
    return [(p.connection.topic, int(p.log_time_ns[i]), p.message(i))
            for p in pieces for i in range(len(p))]


def test_overlapping_files_merge_by_log_time_in_pieces_each_file_in_its_own_order() -> None:
    # Two sonar topics in one file: each of its chunks gives one batch per topic.
    sonar = FakeSource("sonar.mcap", {"/front": stream("/front", 0, 10, 100, b"f"),
                                      "/rear": stream("/rear", 0.002, 10, 100, b"r")},
                       batch_s=4)
    odom = FakeSource("odom.mcap", {"/odom": stream("/odom", 0.05, 10, 20, b"o")},
                      msgtypes={"/odom": "nav_msgs/msg/Odometry"})
    src = MultiSource([odom, sonar], max_gap_s=10)
    pieces = list(src.raw_batches([c.id for c in src.connections]))
    got = [(p.connection.topic, int(t)) for p in pieces for t in p.log_time_ns]
    # Every message once, each topic's messages in their order.
    expected = [(tp, t) for f in (sonar, odom) for tp, m in f._messages.items() for t, _ in m]
    assert sorted(got) == sorted(expected)
    for topic in ("/front", "/rear", "/odom"):
        mine = [t for tp, t in got if tp == topic]
        assert mine == sorted(mine) and len(mine) in (199, 1000)
    # The pieces of a chunk stay together: as the reader sees the stream, nothing comes
    # more than the merge slack late (the ingest reorders 2 s).
    assert lateness(as_the_reader_sees_it(pieces)) <= MERGE_SLACK_NS
    assert lateness(np.array([t for _, t in got])) > MERGE_SLACK_NS  # /rear after /front
    # Cut where the other file's next chunk begins, in pieces of about the slack (not
    # message by message): 10 s of two files.
    assert 10 <= len(pieces) <= 3 * 10 / (MERGE_SLACK_NS / S) + 10
    assert src.duplicates_read_once == 0


def test_files_are_ordered_by_start_whatever_order_they_are_named_in() -> None:
    a = FakeSource("run_0.mcap", {"/sonar": stream("/sonar", 0, 5, 10, b"a")})
    b = FakeSource("run_1.mcap", {"/sonar": stream("/sonar", 5, 10, 10, b"b")})
    one = read_all(MultiSource([b, a], max_gap_s=1))
    two = read_all(MultiSource([a, b], max_gap_s=1))
    assert one == two
    assert [t for _, t, _ in one] == sorted(t for _, t, _ in one)
    merged = MultiSource([b, a], max_gap_s=1)
    assert merged.notes == []  # one after the other: no message can be in both
    assert [f.path for f in merged.files] == ["run_0.mcap", "run_1.mcap"]
    assert str(merged.path) == "run_0.mcap + run_1.mcap"
    assert [c.topic for c in merged.connections] == ["/sonar"]
    assert merged.connections[0].count == 100
    assert (merged.start_ns, merged.end_ns) == (T0, T0 + int(9.9 * S))


def test_identical_messages_in_two_files_are_read_once_and_counted() -> None:
    msgs = stream("/sonar", 0, 4, 50, b"s")
    a = FakeSource("a.mcap", {"/sonar": msgs, "/tf_static": [(T0, b"tf")]},
                   msgtypes={"/tf_static": "tf2_msgs/msg/TFMessage"})
    # b: the same messages, a different batching, the first second's bytes changed.
    changed = [(t, d + (b"x" if t < T0 + S else b"")) for t, d in msgs]
    b = FakeSource("b.mcap", {"/sonar": changed, "/tf_static": [(T0, b"tf")]}, batch_s=0.7,
                   msgtypes={"/tf_static": "tf2_msgs/msg/TFMessage"})
    src = MultiSource([a, b], max_gap_s=1)
    # Before any pass (what `info` sees): the per-file counts may hold a copy twice.
    assert src.notes == ["a.mcap and b.mcap overlap in time on a topic they share: a message "
                         "stored in both counts twice in these per-file counts; reading the "
                         "log keeps one copy (duplicates_read_once in metrics.json)"]
    assert src.connections[0].count + src.connections[1].count == 2 * (len(msgs) + 1)
    got = read_all(src)
    sonar = [(t, d) for tp, t, d in got if tp == "/sonar"]
    # Same topic, time and bytes: once; the changed messages of b (same time) are kept.
    assert sorted(sonar) == sorted(set(msgs) | set(changed))
    assert [d for tp, _, d in got if tp == "/tf_static"] == [b"tf"]
    assert src.duplicates_read_once == (len(msgs) - 50) + 1
    assert "read once: 150 on /sonar, 1 on /tf_static" in src.notes[0]
    # A second pass meets the same duplicates: still counted once.
    read_all(src)
    assert src.duplicates_read_once == 151


def test_a_topic_with_two_types_is_refused_naming_both_files() -> None:
    a = FakeSource("a.mcap", {"/sonar": stream("/sonar", 0, 1, 10, b"a")})
    b = FakeSource("b.mcap", {"/sonar": stream("/sonar", 1, 2, 10, b"b")},
                   msgtypes={"/sonar": "sensor_msgs/msg/PointCloud"})
    with pytest.raises(FormatError, match=r"topic /sonar is sensor_msgs/msg/Range in a.mcap "
                       r"but sensor_msgs/msg/PointCloud in b.mcap"):
        MultiSource([a, b], max_gap_s=10)
    assert a.closed and b.closed


def test_files_further_apart_than_the_gap_limit_are_refused_with_both_spans() -> None:
    a = FakeSource("a.mcap", {"/sonar": stream("/sonar", 0, 10, 10, b"a")})
    b = FakeSource("b.mcap", {"/sonar": stream("/sonar", 40, 50, 10, b"b")})
    c = FakeSource("c.mcap", {"/odom": stream("/odom", 0, 50, 10, b"c")},
                   msgtypes={"/odom": "nav_msgs/msg/Odometry"})
    with pytest.raises(FormatError) as err:
        MultiSource([b, a], max_gap_s=10)
    msg = str(err.value)
    assert "a.mcap (2023-11-14 22:13:20.000-22:13:29.900 UTC) and b.mcap " \
           "(2023-11-14 22:14:00.000-22:14:09.900 UTC) are 30.1 s apart: not one recording" in msg
    assert "input.max_file_gap_s = 10 s" in msg
    assert a.closed and b.closed
    # Within the limit, or bridged by a file that overlaps both: one recording.
    MultiSource([FakeSource("a.mcap", a._messages), FakeSource("b.mcap", b._messages)],
                max_gap_s=31)
    assert len(MultiSource([a, b, c], max_gap_s=0).files) == 3


def test_formats_must_agree_and_empty_files_are_refused() -> None:
    a = FakeSource("a.bag", {"/sonar": stream("/sonar", 0, 1, 10, b"a")}, format_name="ros1")
    b = FakeSource("b.mcap", {"/sonar": stream("/sonar", 1, 2, 10, b"b")})
    with pytest.raises(FormatError, match=r"one format: a\.bag is ros1, b\.mcap is mcap"):
        MultiSource([a, b], max_gap_s=10)
    empty = FakeSource("empty.mcap", {"/sonar": []})
    with pytest.raises(FormatError, match=r"empty\.mcap: holds no messages"):
        MultiSource([b, empty], max_gap_s=10)


def test_losses_are_reported_per_file_and_bytes_lost_summed() -> None:
    a = FakeSource("a.mcap", {"/sonar": stream("/sonar", 0, 1, 10, b"a")},
                   warnings=["chunk at byte 10 is cut off"], bytes_lost=100)
    b = FakeSource("b.mcap", {"/sonar": stream("/sonar", 1, 2, 10, b"b")},
                   warnings=["truncated: 23 bytes lost"], bytes_lost=23)
    # A split cut before its first intact message: its loss counts, it has no span.
    c = FakeSource("c.mcap", {"/sonar": []}, warnings=["corrupt chunk at byte 0 skipped"],
                   bytes_lost=4000)
    src = MultiSource([c, a, b], max_gap_s=10)
    assert src.warnings == ["a.mcap: chunk at byte 10 is cut off",
                            "b.mcap: truncated: 23 bytes lost",
                            "c.mcap: corrupt chunk at byte 0 skipped"]
    assert src.bytes_lost == 4123
    assert [f.path for f in src.files] == ["a.mcap", "b.mcap", "c.mcap"]
    assert len(read_all(src)) == 20


# -- real files through open_log -------------------------------------------------------


def _readings(reader: object) -> tuple[RangeBatch, list[str], np.ndarray]:
    ranges, poses = [], []
    for b in reader.batches():  # type: ignore[attr-defined]
        if isinstance(b, RangeBatch):
            ranges.append(b)
        elif isinstance(b, PoseBatch):
            poses.append(np.column_stack([b.t_ns, b.x, b.y, b.yaw]))
    r = RangeBatch.concat(ranges)
    r = r.take(np.lexsort((r.range_m, r.sensor_id, r.t_ns)))
    names = reader.sensor_names  # type: ignore[attr-defined]
    return r, [names[i] for i in r.sensor_id.tolist()], np.concatenate(poses)


@pytest.fixture(scope="module")
def office_parts(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[Path]]:
    d = tmp_path_factory.mktemp("office-parts")
    t_split = T0 + 50 * S
    split_mcap(OFFICE, [(d / "run_0.mcap", before(t_split)), (d / "run_1.mcap", anything())])
    split_mcap(OFFICE, [(d / "odom.mcap", topics("/odom")), (d / "sonar.mcap", anything())])
    return {"time": [d / "run_1.mcap", d / "run_0.mcap"],
            "topic": [d / "sonar.mcap", d / "odom.mcap"]}


@pytest.mark.parametrize("split", ["time", "topic"])
def test_open_log_reads_the_parts_as_the_whole(office_parts: dict[str, list[Path]],
                                               split: str) -> None:
    with open_log(OFFICE) as whole, open_log(office_parts[split]) as parts:
        w_ranges, w_names, w_poses = _readings(whole)
        p_ranges, p_names, p_poses = _readings(parts)
        info = parts.info()
    assert len(w_ranges) == 8469
    assert p_names == w_names
    for f in ("t_ns", "range_m", "fov_rad", "min_range_m", "max_range_m", "record_t_ns"):
        np.testing.assert_array_equal(getattr(p_ranges, f), getattr(w_ranges, f))
    np.testing.assert_array_equal(p_poses, w_poses)
    assert info.message_count == 10589
    assert [Path(f.path).name for f in info.files] == sorted(p.name for p in office_parts[split])
    assert info.range_topics == ["/sonar"] and info.pose_topic == "/odom"
    assert info.bytes_lost == 0 and info.losses == []


def test_open_log_refuses_what_cannot_be_one_recording(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match=r"office.mcap: is given twice"):
        open_log([OFFICE, OFFICE.parent / "." / OFFICE.name])
    with pytest.raises(FormatError, match=r"one format: .*office\.mcap is mcap, .*office\.bag is ros1"):
        open_log([OFFICE, OFFICE.with_suffix(".bag")])
    csv = OFFICE.parent / "office_csv"
    other = tmp_path / "csv2"
    shutil.copytree(csv, other)
    with pytest.raises(FormatError, match="office_csv: is a csv log: several files are read as "
                       "one recording for ROS 1 bags, ROS 2 bags and MCAP files"):
        open_log([csv, other])
    with pytest.raises(FormatError, match=r"missing\.mcap: no such file"):
        open_log([OFFICE, tmp_path / "missing.mcap"])


@settings(max_examples=60, deadline=None)
@given(
    cuts=st.lists(st.floats(0.1, 9.9), min_size=0, max_size=3),
    by_topic=st.booleans(),
    batch_s=st.lists(st.floats(0.05, 5.0), min_size=4, max_size=4),
    rates=st.tuples(st.integers(1, 80), st.integers(1, 80)),
)
def test_any_split_of_a_recording_reads_back_as_the_recording(
    cuts: list[float], by_topic: bool, batch_s: list[float], rates: tuple[int, int]
) -> None:
    """Property: cut by time (split bags) or by topic (sonar/odometry bags), batched any
    way, the files give every message once, each topic in order, and the reader sees
    them in log order within the merge slack."""
    whole = {"/sonar": stream("/sonar", 0, 10, rates[0], b"s"),
             "/odom": stream("/odom", 0.01, 10, rates[1], b"o")}
    bounds = [T0, *sorted(T0 + int(c * S) for c in cuts), T0 + 11 * S]
    parts: list[dict[str, list[tuple[int, bytes]]]] = []
    if by_topic:
        parts = [{"/sonar": whole["/sonar"]}, {"/odom": whole["/odom"]}]
    else:
        for lo, hi in itertools.pairwise(bounds):
            part = {t: [m for m in msgs if lo <= m[0] < hi] for t, msgs in whole.items()}
            if any(part.values()):
                parts.append({t: m for t, m in part.items() if m})
    if len(parts) < 2:
        return
    sources = [FakeSource(f"p{i}.mcap", p, batch_s=batch_s[i % 4],
                          msgtypes={"/odom": "nav_msgs/msg/Odometry"})
               for i, p in enumerate(parts)]
    src = MultiSource(sources, max_gap_s=10)
    got = read_all(src)
    assert sorted(got) == sorted((t, s, d) for t, msgs in whole.items() for s, d in msgs)
    for topic, msgs in whole.items():
        assert [(s, d) for tp, s, d in got if tp == topic] == msgs
    # As the reader sees it (a chunk's batches sorted together), in log order within the
    # merge slack.
    pieces = list(src.raw_batches([c.id for c in src.connections]))
    assert lateness(as_the_reader_sees_it(pieces)) <= MERGE_SLACK_NS


def test_a_batch_out_of_time_order_does_not_stall_the_merge() -> None:
    """A corrupt stamp puts a batch out of order ([5 s, 1 s]): the merge still ends,
    giving every message once (it once looped forever on such a batch)."""
    from formats.ros.multi_source import _merge_by_time
    from formats.ros.source import Connection, RawBatch

    conn = Connection(id=1, topic="/t", msgtype="std_msgs/msg/Empty", encoding="cdr",
                      msgdef="", msgdef_format="", count=0)
    buf = np.zeros(8, np.uint8)

    def batch(times: list[int]) -> RawBatch:
        n = len(times)
        return RawBatch(conn, np.array(times, np.int64), buf, np.zeros(n, np.int64),
                        np.zeros(n, np.int64))

    s = 10**9
    out = list(_merge_by_time([iter([batch([5 * s, 1 * s])]), iter([batch([3 * s, 4 * s])])],
                              slack_ns=0))
    times = sorted(t for _, raw in out for t in raw.log_time_ns.tolist())
    assert times == [1 * s, 3 * s, 4 * s, 5 * s]
