"""Ros1BagSource: the container layer (records, chunks, index, recovery)."""

from __future__ import annotations

import hashlib
import struct
from pathlib import Path

import numpy as np
import pytest
from ros1_bags import DATA, NS, Msg, range_msg, write_bag
from rosbags.rosbag1 import Reader

from formats.errors import FormatError
from formats.ros.ros1bag import Ros1BagSource
from formats.ros.source import normalize_msgtype

# Per-topic counts of the rosbag.js example bags, as ROS's rosbag library (and rosbags'
# reader, checked once when writing this test) reports them.
EXAMPLE_COUNTS = {
    "/rosout": 10,
    "/turtle1/color_sensor": 1351,
    "/tf_static": 1,
    "/turtle2/color_sensor": 1344,
    "/turtle1/pose": 1344,
    "/turtle2/pose": 1344,
    "/tf": 2688,
    "/turtle2/cmd_vel": 208,
    "/turtle1/cmd_vel": 357,
}


def _topic_counts(src: Ros1BagSource) -> dict[str, int]:
    out: dict[str, int] = {}
    for c in src.connections:
        out[c.topic] = out.get(c.topic, 0) + c.count
    return out


def _read_all(src: Ros1BagSource) -> list[tuple[str, int, bytes]]:
    """(topic, log time, message bytes) of every message, in the order yielded."""
    out = []
    for rb in src.raw_batches([c.id for c in src.connections]):
        out += [
            (rb.connection.topic, int(rb.log_time_ns[i]), rb.message(i)) for i in range(len(rb))
        ]
    return out


def _digest(msgs: list[tuple[str, int, bytes]]) -> str:
    h = hashlib.sha256()
    for topic, t, data in sorted(msgs):
        h.update(topic.encode() + t.to_bytes(8, "little") + data)
    return h.hexdigest()


@pytest.mark.parametrize("name", ["example-lz4.bag", "example-bz2.bag"])
def test_example_counts_match_rosbag(name: str) -> None:
    with Ros1BagSource(DATA / name) as src:
        assert _topic_counts(src) == EXAMPLE_COUNTS
        msgs = _read_all(src)
        assert src.warnings == []
        assert src.chunk_count == 1
        assert src.start_ns == 1396293887844783943
        assert src.end_ns == 1396293909544870199
        types = {c.topic: c.msgtype for c in src.connections}
    yielded: dict[str, int] = {}
    for topic, _t, _d in msgs:
        yielded[topic] = yielded.get(topic, 0) + 1
    assert yielded == EXAMPLE_COUNTS
    assert types["/tf"] == "tf/msg/tfMessage"
    assert types["/tf_static"] == "tf2_msgs/msg/TFMessage"
    assert types["/turtle1/pose"] == "turtlesim/msg/Pose"


def test_lz4_and_bz2_examples_hold_the_same_messages() -> None:
    with Ros1BagSource(DATA / "example-lz4.bag") as a, Ros1BagSource(DATA / "example-bz2.bag") as b:
        ma, mb = _read_all(a), _read_all(b)
    assert len(ma) == 8647
    assert _digest(ma) == _digest(mb)


def test_connections_carry_definition_and_md5() -> None:
    with Ros1BagSource(DATA / "tiago-sonar.bag") as src:
        (c,) = src.connections
    assert (c.topic, c.msgtype, c.count, c.encoding) == (
        "/sonar_base",
        "sensor_msgs/msg/Range",
        609,
        "ros1",
    )
    assert c.msgdef_format == "ros1msg"
    assert c.msgdef.startswith("# Single range reading")
    assert c.md5sum == "c005c34273dc426c67a020a87bc24148"


def test_unsorted_chunks_come_out_in_time_order() -> None:
    with Ros1BagSource(DATA / "example-unsorted-chunks.bag") as src:
        msgs = _read_all(src)
        assert (src.start_ns, src.end_ns) == (1 * NS, 3 * NS)
    assert [(t, d) for _topic, t, d in msgs] == [
        (1 * NS, b"\x01\x00\x00\x001"),
        (2 * NS, b"\x01\x00\x00\x002"),
        (3 * NS, b"\x01\x00\x00\x003"),
    ]


def test_bag_without_messages() -> None:
    with Ros1BagSource(DATA / "no-messages.bag") as src:
        assert src.connections == []
        assert (src.start_ns, src.end_ns) == (None, None)
        assert list(src.raw_batches([0, 1])) == []
        assert src.warnings == []


def test_empty_file_is_a_format_error() -> None:
    with pytest.raises(FormatError, match=r"empty-file\.bag: empty file \(0 bytes\)"):
        Ros1BagSource(DATA / "empty-file.bag")


def test_not_a_bag(tmp_path: Path) -> None:
    p = tmp_path / "notes.bag"
    p.write_text("hello, this is text\n" * 10)
    with pytest.raises(FormatError, match=r"notes\.bag: not a ROS 1 bag"):
        Ros1BagSource(p)
    old = tmp_path / "old.bag"
    old.write_bytes(b"#ROSBAG V1.2\n" + bytes(100))
    with pytest.raises(FormatError, match=r"version 1\.2 is not supported"):
        Ros1BagSource(old)
    missing = tmp_path / "missing.bag"
    with pytest.raises(FormatError, match=r"missing\.bag: cannot open"):
        Ros1BagSource(missing)


def test_msgtype_normalisation() -> None:
    assert normalize_msgtype("sensor_msgs/Range") == "sensor_msgs/msg/Range"
    assert normalize_msgtype("tf/tfMessage") == "tf/msg/tfMessage"
    assert normalize_msgtype("sensor_msgs/msg/Range") == "sensor_msgs/msg/Range"
    assert normalize_msgtype("Weird") == "Weird"


# ------------------------------------------------------------------ generated bags


def _range_bag(path: Path, n: int = 60, **kw: object) -> Path:
    msgs = [
        Msg(
            "/sonar",
            "sensor_msgs/msg/Range",
            NS + i * 10_000_000,
            range_msg(NS + i * 10_000_000, f"s{i % 3}", 0.5 + i),
        )
        for i in range(n)
    ]
    return write_bag(path, msgs, **kw)  # type: ignore[arg-type]


@pytest.mark.parametrize("compression", ["none", "bz2", "lz4"])
def test_generated_bag_chunks_match_rosbags_reader(tmp_path: Path, compression: str) -> None:
    p = _range_bag(tmp_path / "r.bag", compression=compression, chunk_threshold=500)
    with Reader(p) as ref:
        expected = [(c.topic, t, bytes(d)) for c, t, d in ref.messages()]
        ref_chunks = len(ref.chunk_infos)
    with Ros1BagSource(p) as src:
        got = _read_all(src)
        assert src.chunk_count == ref_chunks > 5
    assert got == expected


def test_several_connections_on_one_topic(tmp_path: Path) -> None:
    p = _range_bag(tmp_path / "r.bag", n=10, extra_connections=2)
    with Ros1BagSource(p) as src:
        assert [(c.id, c.topic, c.count) for c in src.connections] == [
            (0, "/sonar", 4),
            (1, "/sonar", 3),
            (2, "/sonar", 3),
        ]
        batches = list(src.raw_batches([1]))
    assert [len(b) for b in batches] == [3]
    assert batches[0].log_time_ns.tolist() == [NS + k * 10_000_000 for k in (1, 4, 7)]


def test_messages_written_out_of_order_are_sorted(tmp_path: Path) -> None:
    times = [5, 3, 9, 1, 7, 2, 8, 0, 6, 4]
    msgs = [
        Msg("/sonar", "sensor_msgs/msg/Range", NS + t, range_msg(NS + t, "s", float(t)))
        for t in times
    ]
    p = write_bag(tmp_path / "u.bag", msgs, chunk_threshold=150)
    with Reader(p) as ref:
        spans = sorted((ci.start_time, ci.end_time) for ci in ref.chunk_infos)
    assert len(spans) > 2 and spans[1][0] < spans[0][1]  # chunks overlap in time
    with Ros1BagSource(p) as src:
        batches = list(src.raw_batches([0]))
    got = [int(t) for rb in batches for t in rb.log_time_ns]
    assert got == [NS + t for t in range(10)]
    values = [rb.message(i)[-4:] for rb in batches for i in range(len(rb))]
    assert values == [struct.pack("<f", float(t)) for t in range(10)]


# ------------------------------------------------------------------ damaged bags


def _index_pos(p: Path) -> int:
    data = p.read_bytes()
    k = data.index(b"index_pos=") + len(b"index_pos=")
    return int(struct.unpack_from("<Q", data, k)[0])


def _chunk_positions(p: Path) -> list[int]:
    with Reader(p) as ref:
        return [ci.pos for ci in ref.chunk_infos]


def _truncate(src: Path, dst: Path, size: int) -> Path:
    dst.write_bytes(src.read_bytes()[:size])
    return dst


def test_truncated_inside_bag_header(tmp_path: Path) -> None:
    p = _range_bag(tmp_path / "r.bag")
    cut = _truncate(p, tmp_path / "cut.bag", 30)
    with pytest.raises(FormatError, match=r"cut\.bag: corrupt bag header"):
        Ros1BagSource(cut)


def test_truncated_at_chunk_boundary_keeps_complete_chunks(tmp_path: Path) -> None:
    p = _range_bag(tmp_path / "r.bag", chunk_threshold=500)
    with Ros1BagSource(p) as src:
        full = _read_all(src)
    pos = _chunk_positions(p)
    cut = _truncate(p, tmp_path / "cut.bag", pos[3])
    with Ros1BagSource(cut) as src:
        got = _read_all(src)
        (warning,) = src.warnings
    with Reader(p) as ref:
        in_first_three = sum(sum(ci.connection_counts.values()) for ci in ref.chunk_infos[:3])
    assert got == full[:in_first_three]
    assert warning == (
        f"{cut}: index position {_index_pos(p)} is outside the file ({pos[3]} bytes): "
        f"read by scanning, {in_first_three} messages recovered, 0 bytes at the end lost"
    )


def test_truncated_inside_uncompressed_chunk_recovers_its_intact_messages(tmp_path: Path) -> None:
    p = _range_bag(tmp_path / "r.bag", chunk_threshold=2000)
    with Ros1BagSource(p) as src:
        full = _read_all(src)
    pos = _chunk_positions(p)
    cut = _truncate(p, tmp_path / "cut.bag", pos[1] + 400)
    with Ros1BagSource(cut) as src:
        got = _read_all(src)
        (warning,) = src.warnings
    with Reader(p) as ref:
        first = sum(ref.chunk_infos[0].connection_counts.values())
    assert first < len(got) < len(full)
    assert got == full[: len(got)]
    assert f"of them from a cut-off chunk), {400} bytes at the end lost" in warning


def test_truncated_inside_index_recovers_everything(tmp_path: Path) -> None:
    p = _range_bag(tmp_path / "r.bag", chunk_threshold=500)
    with Ros1BagSource(p) as src:
        full = _read_all(src)
    cut = _truncate(p, tmp_path / "cut.bag", _index_pos(p) + 30)
    with Ros1BagSource(cut) as src:
        got = _read_all(src)
        (warning,) = src.warnings
    assert got == full
    assert "is unreadable" in warning
    assert "60 messages recovered, 30 bytes at the end lost" in warning


@pytest.mark.parametrize("compression", ["none", "bz2", "lz4"])
def test_truncated_anywhere_gives_a_prefix_or_a_format_error(
    tmp_path: Path, compression: str
) -> None:
    p = _range_bag(tmp_path / "r.bag", n=40, compression=compression, chunk_threshold=600)
    with Ros1BagSource(p) as src:
        full = _read_all(src)
    size = p.stat().st_size
    outcomes = {"error": 0, "prefix": 0}
    # A few cuts inside the magic line and the 4 KiB bag header, the rest after it.
    cuts = [5, 20, 2000, *np.linspace(4109, size - 1, 40).astype(int).tolist()]
    for k, cut_at in enumerate(cuts):
        cut = _truncate(p, tmp_path / f"cut{k}.bag", int(cut_at))
        try:
            with Ros1BagSource(cut) as src:
                got = _read_all(src)
                assert len(src.warnings) == 1
        except FormatError as err:
            assert str(err).startswith(str(cut))
            outcomes["error"] += 1
            continue
        assert got == full[: len(got)]
        outcomes["prefix"] += 1
    assert outcomes == {"error": 3, "prefix": 40}


def test_unindexed_bag_is_scanned(tmp_path: Path) -> None:
    p = _range_bag(tmp_path / "r.bag", chunk_threshold=500)
    with Ros1BagSource(p) as src:
        full = _read_all(src)
    data = bytearray(p.read_bytes())
    k = data.index(b"index_pos=") + len(b"index_pos=")
    data[k : k + 8] = bytes(8)
    q = tmp_path / "unindexed.bag"
    q.write_bytes(bytes(data))
    with Ros1BagSource(q) as src:
        assert _read_all(src) == full
        assert src.warnings == [
            f"{q}: bag is not indexed (index_pos 0, recording not closed): read by scanning, "
            "60 messages recovered, 0 bytes at the end lost"
        ]
        assert [c.count for c in src.connections] == [60]


def _lost_chunk(src: Ros1BagSource, full: list[tuple[str, int, bytes]], pos: int,
                reason: str) -> None:
    """The chunk at ``pos`` is skipped and recorded as a loss; every other one is read."""
    got = _read_all(src)
    assert got and set(got) < set(full)
    assert len(src.warnings) == 1 and f"corrupt chunk at byte {pos} skipped (" in src.warnings[0]
    assert reason in src.warnings[0]
    assert src.bytes_lost > 0 and src.messages_lost == len(full) - len(got)
    again = _read_all(src)  # a second pass meets the loss again: counted once
    assert again == got and len(src.warnings) == 1 and src.messages_lost == len(full) - len(got)


def test_corrupt_chunk_compression_field(tmp_path: Path) -> None:
    p = _range_bag(tmp_path / "r.bag", chunk_threshold=500)
    with Ros1BagSource(p) as src:
        full = _read_all(src)
    pos = _chunk_positions(p)
    data = p.read_bytes().replace(b"compression=none", b"compression=zzzz", 1)
    q = tmp_path / "bad.bag"
    q.write_bytes(data)
    with Ros1BagSource(q) as src:
        _lost_chunk(src, full, pos[0], "unknown chunk compression 'zzzz'")


def test_corrupt_chunk_header_length(tmp_path: Path) -> None:
    p = _range_bag(tmp_path / "r.bag", chunk_threshold=500)
    with Ros1BagSource(p) as src:
        full = _read_all(src)
    pos = _chunk_positions(p)
    data = bytearray(p.read_bytes())
    data[pos[2] : pos[2] + 4] = b"\xff\xff\xff\x7f"
    q = tmp_path / "bad.bag"
    q.write_bytes(bytes(data))
    with Ros1BagSource(q) as src:
        _lost_chunk(src, full, pos[2], f"record at byte {pos[2]} has an implausible")
        assert src.bytes_lost == pos[3] - pos[2]  # the chunk and its index records


def test_corrupt_lz4_data(tmp_path: Path) -> None:
    p = _range_bag(tmp_path / "r.bag", compression="lz4", chunk_threshold=500)
    with Ros1BagSource(p) as src:
        full = _read_all(src)
    pos = _chunk_positions(p)[0]
    data = bytearray(p.read_bytes())
    # Inside the compressed data: past the chunk header (~45 bytes) and the frame header.
    for k in range(pos + 70, pos + 90):
        data[k] ^= 0x5A
    q = tmp_path / "bad.bag"
    q.write_bytes(bytes(data))
    with Ros1BagSource(q) as src:
        _lost_chunk(src, full, pos, "")  # lz4 frames carry no checksum: bad data or records
