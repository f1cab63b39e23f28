"""Broken MCAP files, bags and CDR messages: intact part + warning, or FormatError."""

from __future__ import annotations

import shutil
import struct
import tempfile
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2.enums import CompressionMode
from test_ros2_written_bags import JAZZY, N, write_bag

from formats.errors import FormatError
from formats.ros.columns import RangeColumns
from formats.ros.decode_cdr import decode_cdr
from formats.ros.mcap_source import McapSource
from formats.ros.ros2bag import Ros2BagSource
from formats.ros.source import RawBatch


@pytest.fixture
def mcap_bag(tmp_path: Path) -> Path:
    """A rosbags-written MCAP (several chunks of zstd-compressed records)."""
    return write_bag(tmp_path / "bag", JAZZY, StoragePlugin.MCAP, CompressionMode.STORAGE)


def _count(src: McapSource | Ros2BagSource) -> int:
    return sum(len(b) for b in src.raw_batches([c.id for c in src.connections]))


def test_zero_byte_file(tmp_path: Path) -> None:
    (tmp_path / "x.mcap").write_bytes(b"")
    with pytest.raises(FormatError, match=r"x\.mcap: empty file \(0 bytes\)"):
        McapSource(tmp_path / "x.mcap")
    (tmp_path / "x.db3").write_bytes(b"")
    with pytest.raises(FormatError, match=r"x\.db3: empty file"):
        Ros2BagSource(tmp_path / "x.db3")


def test_not_an_mcap(tmp_path: Path) -> None:
    (tmp_path / "x.mcap").write_bytes(b"#ROSBAG V2.0\n" + b"\0" * 100)
    with pytest.raises(FormatError, match=r"x\.mcap: not an MCAP file \(bad magic bytes\)"):
        McapSource(tmp_path / "x.mcap")


def test_garbage_sqlite(tmp_path: Path) -> None:
    (tmp_path / "x.db3").write_bytes(b"this is not a database " * 100)
    with pytest.raises(FormatError, match=r"x\.db3: not a readable rosbag2 sqlite3 database"):
        Ros2BagSource(tmp_path / "x.db3")


def test_truncated_sqlite(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "bag", JAZZY, StoragePlugin.SQLITE3, CompressionMode.NONE)
    db = bag / "bag.db3"
    data = db.read_bytes()
    db.write_bytes(data[: len(data) // 2])
    # Either the intact part with a warning, or an error naming the file; nothing else.
    try:
        with Ros2BagSource(bag) as src:
            n = _count(src)
            assert n < N + 21 and src.warnings
    except FormatError as err:
        assert "bag.db3" in str(err)


def test_mcap_truncated_at_several_offsets(mcap_bag: Path, tmp_path: Path) -> None:
    data = (mcap_bag / "bag.mcap").read_bytes()
    total = N + 21
    cut_path = tmp_path / "cut.mcap"
    seen = set()
    for cut in [len(data) - 1, len(data) - 40, len(data) * 3 // 4, len(data) // 2, 100, 30, 12]:
        cut_path.write_bytes(data[:cut])
        try:
            with McapSource(cut_path) as src:
                n = _count(src)
                assert n <= total
                assert src.warnings[0].startswith("no end magic")
                seen.add("intact" if n == total else "partial")
        except FormatError as err:
            assert str(err).startswith(str(cut_path))
            seen.add("error")
    assert seen == {"intact", "error"} or "partial" in seen


def test_mcap_truncated_inside_chunk_reports_bytes_lost(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "bag", JAZZY, StoragePlugin.MCAP, CompressionMode.NONE)
    data = (bag / "bag.mcap").read_bytes()
    # The first chunk record starts after magic (8) and the header record.
    (hlen,) = struct.unpack_from("<Q", data, 9)
    chunk_at = 8 + 9 + hlen
    assert data[chunk_at] == 0x06
    (tmp_path / "cut.mcap").write_bytes(data[: chunk_at + 50])
    with McapSource(tmp_path / "cut.mcap") as src:
        assert _count(src) == 0
        assert any(
            f"record at byte {chunk_at} (opcode 0x06)" in w and "50 bytes lost" in w
            for w in src.warnings
        ), src.warnings


def test_corrupt_chunk_compression(mcap_bag: Path) -> None:
    path = mcap_bag / "bag.mcap"
    data = bytearray(path.read_bytes())
    (hlen,) = struct.unpack_from("<Q", data, 9)
    chunk_at = 8 + 9 + hlen
    # Records start after start/end/size (24), crc (4), 'zstd' (4 + 4), records length (8).
    records_at = chunk_at + 9 + 24 + 4 + 8 + 8
    data[records_at : records_at + 16] = b"\xff" * 16
    path.write_bytes(bytes(data))
    with McapSource(path) as src:
        assert _count(src) == 0  # everything sits in that one chunk
        assert len(src.warnings) == 1
        assert src.warnings[0].startswith(f"corrupt chunk at byte {chunk_at} skipped (")
    with Ros2BagSource(mcap_bag) as bag:
        _count(bag)
        assert bag.warnings[0].startswith("bag.mcap: corrupt chunk")


def test_metadata_naming_missing_file(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "bag", JAZZY, StoragePlugin.SQLITE3, CompressionMode.NONE)
    meta = bag / "metadata.yaml"
    meta.write_text(meta.read_text().replace("- bag.db3", "- bag.db3\n  - bag_1.db3", 1))
    with pytest.raises(FormatError, match=r"bag_1\.db3: storage file bag_1\.db3 listed"):
        Ros2BagSource(bag)


def test_unreadable_metadata(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "bag", JAZZY, StoragePlugin.SQLITE3, CompressionMode.NONE)
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: 99}\n")
    with pytest.raises(FormatError, match=r"metadata\.yaml: unreadable rosbag2 metadata"):
        Ros2BagSource(bag)


def test_corrupt_file_compression(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "bag", JAZZY, StoragePlugin.SQLITE3, CompressionMode.FILE)
    (bag / "bag.db3.zstd").write_bytes(b"\x28\xb5\x2f\xfd" + b"\x00" * 20)
    with pytest.raises(FormatError, match=r"bag\.db3\.zstd: cannot decompress zstd file"):
        Ros2BagSource(bag)


def test_file_compressed_bag_cleans_its_temp_copy(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    bag = write_bag(tmp_path / "bag", JAZZY, StoragePlugin.MCAP, CompressionMode.FILE)
    temp_root = tmp_path / "temp"
    temp_root.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp_root))
    src = Ros2BagSource(bag)
    copies = list(temp_root.glob("*/bag.mcap"))
    assert len(copies) == 1  # the decompressed copy, while the bag is open
    assert _count(src) == N + 21
    src.close()
    assert list(temp_root.iterdir()) == []


def _range_batch(datas: list[bytes]) -> RawBatch:
    from formats.ros.source import Connection

    lengths = np.array([len(d) for d in datas], np.int64)
    conn = Connection(7, "/sonar", "sensor_msgs/msg/Range", "cdr", "", "", len(datas))
    return RawBatch(
        conn,
        np.arange(len(datas), dtype=np.int64) * 10,
        np.frombuffer(b"".join(datas), np.uint8),
        np.cumsum(lengths) - lengths,
        lengths,
    )


def _good() -> bytes:
    from test_ros2_written_bags import _range

    return bytes(JAZZY.serialize_cdr(_range(JAZZY, 1), "sensor_msgs/msg/Range"))


@pytest.mark.parametrize(
    ("bad", "match"),
    [
        (lambda d: d[:10], "too short for a CDR header"),
        (lambda d: d[:30], "too short for sensor_msgs/msg/Range"),
        (lambda d: b"\x00\x07" + d[2:], "unsupported CDR encapsulation"),
        (lambda d: d[:12] + b"\xff\x00\x00\x00" + d[16:], "frame_id string runs past the end"),
        (lambda d: d[:26] + b"X" + d[27:], "frame_id string is not NUL-terminated"),
    ],
)
def test_malformed_cdr_message(bad: object, match: str) -> None:
    good = _good()
    broken = bad(good)  # type: ignore[operator]
    with pytest.raises(
        FormatError, match=rf"^message 2 of topic /sonar \(log time 20 ns\): {match}"
    ):
        decode_cdr(_range_batch([good, good, broken, good]))


def test_non_cdr_encoding_is_refused() -> None:
    from dataclasses import replace

    raw = _range_batch([_good()])
    raw = RawBatch(
        replace(raw.connection, encoding="other"),
        raw.log_time_ns,
        raw.buffer,
        raw.offsets,
        raw.lengths,
    )
    with pytest.raises(FormatError, match=r"topic /sonar: message encoding 'other' is not CDR"):
        decode_cdr(raw)


def test_missing_fixture_dir_file(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match=r"nothing: no such file or directory"):
        Ros2BagSource(tmp_path / "nothing")
    (tmp_path / "x.txt").write_text("hi")
    with pytest.raises(FormatError, match=r"x\.txt: not a ROS 2 bag"):
        Ros2BagSource(tmp_path / "x.txt")
    shutil.rmtree(tmp_path)


def test_many_frames_keep_first_appearance_order() -> None:
    from test_ros2_written_bags import _header

    rng = np.random.default_rng(3)
    names = [f"f{k}" * (k % 5 + 1) for k in range(40)]  # lengths 2 ... 15 bytes
    picks = rng.integers(0, 40, 500)
    datas = []
    for i, k in enumerate(picks):
        msg = JAZZY.types["sensor_msgs/msg/Range"](
            header=_header(JAZZY, i, names[k]),
            radiation_type=1,
            field_of_view=0.1,
            min_range=0.0,
            max_range=1.0,
            range=float(k),
            variance=0.0,
        )
        datas.append(bytes(JAZZY.serialize_cdr(msg, "sensor_msgs/msg/Range")))
    cols = decode_cdr(_range_batch(datas))
    assert isinstance(cols, RangeColumns)
    decoded = [cols.frames[c] for c in cols.frame]
    assert decoded == [names[k] for k in picks]
    assert cols.frames == list(dict.fromkeys(decoded))
    np.testing.assert_array_equal(cols.range, picks)
