"""Decompression bombs (tiny generated logs whose chunks declare or inflate to gigabytes):
the chunk is refused and recorded as a loss, the rest is mapped, memory stays small."""

from __future__ import annotations

import bz2
import json
import re
import tracemalloc
from pathlib import Path

import lz4.frame
import pytest
from typer.testing import CliRunner

from cli.app import app
from formats.ros.inflate import MAX_CHUNK_BYTES, ChunkError, check_declared, inflate
from fuzz.bombs import mcap_chunk, mcap_declaring, mcap_with_chunk, ros1_declaring, zstd_zeros
from fuzz.harness import ROOT, read_with_losses

OFFICE = ROOT / "sample_logs" / "office"
CORRIDOR = ROOT / "sample_logs" / "corridor" / "corridor.mcap"  # 5 726 messages
GIB = 1 << 30


def _peak_read(path: Path) -> tuple[int, int, int]:
    """(records, losses, traced peak bytes) of reading a whole log."""
    tracemalloc.start()
    try:
        records, losses = read_with_losses(path)
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    return records, losses, peak


def test_zstd_frame_of_zeros_is_tiny_and_inflates_to_its_size() -> None:
    frame = zstd_zeros(3 << 20)
    assert len(frame) == 6 + 4 * 24
    assert bytes(inflate("zstd", frame, 3 << 20)) == bytes(3 << 20)


@pytest.mark.parametrize(
    ("codec", "compressed", "declared", "why"),
    [
        ("zstd", 1 << 20, MAX_CHUNK_BYTES + 1, "more than the 128 MiB a chunk may hold"),
        ("lz4", 1000, 1000 * 255 + 4097, "more than lz4 can inflate (255:1)"),
        ("zstd", 100, 100 * 32_768 + 4097, "more than zstd can inflate (32768:1)"),
        ("none", 100, 101, "uncompressed chunk of 100 bytes declares 101"),
        ("brotli", 100, 100, "unknown chunk compression 'brotli'"),
    ],
)
def test_declared_sizes_beyond_the_bound_are_refused(
    codec: str, compressed: int, declared: int, why: str
) -> None:
    with pytest.raises(ChunkError, match=re.escape(why)):
        check_declared(codec, compressed, declared)
    check_declared("zstd", 1 << 20, MAX_CHUNK_BYTES)  # the bound itself is allowed


@pytest.mark.parametrize("codec", ["zstd", "lz4", "bz2"])
def test_a_stream_inflating_past_its_declared_size_stops_one_byte_after(codec: str) -> None:
    raw = bytes(8 << 20)
    data = {"zstd": zstd_zeros(8 << 20), "lz4": lz4.frame.compress(raw),
            "bz2": bz2.compress(raw)}[codec]
    with pytest.raises(ChunkError, match=rf"{codec} data inflates to more than 1000 bytes"):
        inflate(codec, data, 1000)
    with pytest.raises(ChunkError, match=r"does not decompress|inflates to|can inflate"):
        inflate(codec, data[: len(data) // 2] + bytes(16), 8 << 20)


def test_mcap_chunk_of_4_gib_is_a_loss_and_the_rest_is_mapped(tmp_path: Path) -> None:
    valid = CORRIDOR.read_bytes()
    log = tmp_path / "bomb.mcap"
    log.write_bytes(mcap_with_chunk(valid, mcap_chunk(zstd_zeros(4 * GIB), "zstd", 4 * GIB)))
    assert log.stat().st_size < len(valid) + 200_000
    assert read_with_losses(log) == (read_with_losses(CORRIDOR)[0], 1)
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["run", str(log), "-o", str(out), "-q"])
    assert res.exit_code == 0, res.output
    inp = json.loads((out / "metrics.json").read_text())["input"]
    assert inp["bytes_lost"] > 4 * GIB // 32_768
    (loss,) = inp["losses"]
    assert loss.startswith("bomb.mcap: corrupt chunk at byte ")
    assert "declares 4294967296 uncompressed bytes" in loss


def test_mcap_chunk_declaring_less_than_it_inflates_stops_at_the_declared_size(
    tmp_path: Path,
) -> None:
    valid = CORRIDOR.read_bytes()
    log = tmp_path / "bomb.mcap"
    log.write_bytes(mcap_with_chunk(valid, mcap_chunk(zstd_zeros(4 * GIB), "zstd", 64 << 20)))
    records, losses, peak = _peak_read(log)
    assert records > 5_000 and losses == 1
    assert peak < (64 << 20) + (100 << 20)  # the declared size, never the 4 GiB
    res = CliRunner().invoke(app, ["validate", str(log), "--json"])
    found = {f["code"]: f for f in json.loads(res.stdout)["findings"]}
    assert "inflates to more than 67108864 bytes" in found["damaged_log"]["message"]


def test_mcap_chunk_of_empty_records_is_walked_without_an_object_per_record(
    tmp_path: Path,
) -> None:
    """24 MiB of 9-byte empty records (2.8 M records): 8 bytes of offsets each, not ~15
    bytes of Python objects per decompressed byte."""
    valid = CORRIDOR.read_bytes()
    log = tmp_path / "zeros.mcap"
    size = (24 << 20) // 9 * 9  # whole records: no trailing bytes
    log.write_bytes(mcap_with_chunk(valid, mcap_chunk(zstd_zeros(size), "zstd", size)))
    records, losses, peak = _peak_read(log)
    assert records > 5_000 and losses == 0
    assert peak < 3 * size


def test_every_chunk_declaring_too_much_ends_in_one_line_naming_the_loss(
    tmp_path: Path,
) -> None:
    for name, data in (
        ("all.mcap", mcap_declaring((OFFICE / "office.mcap").read_bytes(), 4 * GIB)),
        ("all.bag", ros1_declaring((OFFICE / "office.bag").read_bytes(), 2 * GIB)),
    ):
        log = tmp_path / name
        log.write_bytes(data)
        out = tmp_path / f"out-{name}"
        res = CliRunner().invoke(app, ["run", str(log), "-o", str(out), "-q"])
        assert res.exit_code == 1 and not out.exists()
        (line,) = res.stderr.splitlines()
        assert "the log is damaged" in line and "corrupt chunk at byte" in line
        assert "more than the 128 MiB a chunk may hold" in line
        res = CliRunner().invoke(app, ["info", str(log)])
        assert res.exit_code == 0, res.output


def test_ros1_chunk_declaring_2_gib_loses_only_that_chunk(tmp_path: Path) -> None:
    data = bytearray((OFFICE / "office.bag").read_bytes())
    second = data.find(b"\x09\x00\x00\x00size=", data.find(b"\x09\x00\x00\x00size=") + 1)
    data[second + 9 : second + 13] = (2 * GIB).to_bytes(4, "little")
    log = tmp_path / "bomb.bag"
    log.write_bytes(bytes(data))
    records, losses, peak = _peak_read(log)
    assert records > 4000 and losses == 1 and peak < 100 << 20
