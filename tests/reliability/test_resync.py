"""Issue 58 item 9, corrupt *framing*: a record header or length that is garbage loses the
bytes up to the next intact record, not the rest of the log (formats/ros/resync.py).

Each case overwrites 64-256 bytes of one record header of the sample office logs (three
chunks each) with seeded random bytes, with the file's index intact and without it (an
unindexed bag, an MCAP file without its summary: then only a forward walk finds the
records), and checks what is read against the intact file."""

from __future__ import annotations

import json
import random
import struct
import tracemalloc
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.app import app
from formats import open_log
from formats.ros.mcap_source import McapSource
from formats.ros.ros1bag import Ros1BagSource
from fuzz.harness import ROOT, Target, check_mutation, read_with_losses
from fuzz.mutators import Mutation

OFFICE = ROOT / "sample_logs" / "office"
BAG, MCAP = OFFICE / "office.bag", OFFICE / "office.mcap"
INTACT = 10607  # topics + messages read from either intact file


def _ros1_records(data: bytes) -> list[tuple[int, int, int]]:
    """(offset, op, length) of the top-level records of a bag."""
    pos, out = 13, []
    while pos + 8 <= len(data):
        hlen = struct.unpack_from("<I", data, pos)[0]
        dlen = struct.unpack_from("<I", data, pos + 4 + hlen)[0]
        header = data[pos + 4 : pos + 4 + hlen]
        op = header[header.index(b"op=") + 3]
        out.append((pos, op, 8 + hlen + dlen))
        pos += 8 + hlen + dlen
    return out


def _mcap_records(data: bytes) -> list[tuple[int, int, int]]:
    pos, out = 8, []
    while pos + 9 <= len(data) - 8:
        op, length = data[pos], struct.unpack_from("<Q", data, pos + 1)[0]
        out.append((pos, op, 9 + length))
        pos += 9 + length
    return out


def _garbage(data: bytes, at: int, n: int) -> bytes:
    rnd = random.Random(at * 1000 + n)
    return data[:at] + bytes(rnd.randrange(256) for _ in range(n)) + data[at + n :]


def _unindexed(bag: bytes) -> bytes:
    k = bag.index(b"index_pos=") + len(b"index_pos=")
    return bag[:k] + bytes(8) + bag[k + 8 :]


def _unfinished(mcap: bytes) -> bytes:
    return mcap[:-8] + bytes(8)  # no end magic: the summary is not trusted, the file scanned


def _read(tmp_path: Path, name: str, data: bytes) -> tuple[int, int]:
    p = tmp_path / name
    p.write_bytes(data)
    return read_with_losses(p)


CHUNK_OPS = {"bag": 0x05, "mcap": 0x06}


@pytest.mark.parametrize("n", [64, 128, 256])
@pytest.mark.parametrize("kind", ["bag", "mcap"])
@pytest.mark.parametrize("indexed", [True, False])
def test_a_garbage_record_header_loses_that_record_only(tmp_path: Path, n: int, kind: str,
                                                        indexed: bool) -> None:
    data = (BAG if kind == "bag" else MCAP).read_bytes()
    records = _ros1_records(data) if kind == "bag" else _mcap_records(data)
    prepare = (lambda d: d) if indexed else (_unindexed if kind == "bag" else _unfinished)
    chunks = [r for r in records if r[1] == CHUNK_OPS[kind]]
    assert len(chunks) == 3
    # The chunks' message counts, from the intact file: what losing each one costs.
    lost_alone = {}
    for pos, op, _length in records[1:]:  # the bag/MCAP header first: tested below
        got, losses = _read(tmp_path, f"x.{kind}", prepare(_garbage(data, pos, n)))
        if op == CHUNK_OPS[kind]:
            lost_alone[pos] = INTACT - got
            assert losses >= 1
        else:  # an index, a connection, a schema, a summary record: every message read
            assert got == INTACT, (pos, op)
    # A damaged chunk loses its messages and no others: the three losses add up to all
    # the messages (the topics are still read), none more than 6/10 of them.
    assert sum(lost_alone.values()) == INTACT - 3
    assert all(0 < v < INTACT * 6 // 10 for v in lost_alone.values())


@pytest.mark.parametrize("kind", ["bag", "mcap"])
def test_a_garbage_file_header_loses_only_its_own_bytes(tmp_path: Path, kind: str) -> None:
    data = (BAG if kind == "bag" else MCAP).read_bytes()
    n = 64 if kind == "bag" else 40  # the MCAP header record is 50 bytes, the first chunk next
    got, losses = _read(tmp_path, f"x.{kind}", _garbage(data, 13 if kind == "bag" else 8, n))
    assert got == INTACT and losses >= 1


def test_the_walk_resumes_after_a_garbage_chunk_header_at_the_same_count(
    tmp_path: Path,
) -> None:
    """Unindexed: the messages read equal those read through the index (the same chunk
    lost), and the skipped bytes are counted."""
    data = BAG.read_bytes()
    second = [r for r in _ros1_records(data) if r[1] == 0x05][1]
    damaged = _garbage(data, second[0], 128)
    assert _read(tmp_path, "a.bag", _unindexed(damaged))[0] == _read(tmp_path, "b.bag",
                                                                       damaged)[0]
    p = tmp_path / "c.bag"
    p.write_bytes(_unindexed(damaged))
    with Ros1BagSource(p) as src:
        # the chunk and its index data records, up to the next chunk
        assert src.bytes_lost >= second[2]
        assert any(f"bytes {second[0]}-" in w and "skipped to the next record" in w
                   for w in src.warnings)


def test_an_mcap_scan_counts_the_skipped_bytes(tmp_path: Path) -> None:
    data = MCAP.read_bytes()
    second = [r for r in _mcap_records(data) if r[1] == 0x06][1]
    p = tmp_path / "u.mcap"
    p.write_bytes(_unfinished(_garbage(data, second[0], 128)))
    with McapSource(p) as src:
        assert src.bytes_lost >= second[2]
        assert any(f"bytes {second[0]}-" in w and "skipped to the next record" in w
                   for w in src.warnings)


@pytest.mark.parametrize("kind", ["bag", "mcap"])
def test_megabytes_of_garbage_mid_file_are_skipped_in_bounded_memory(tmp_path: Path,
                                                                     kind: str) -> None:
    """8 MiB of random bytes between two records of an unindexed file: every message
    outside them is read, with at most a few MiB allocated (the search reads windows)."""
    data = (BAG if kind == "bag" else MCAP).read_bytes()
    records = _ros1_records(data) if kind == "bag" else _mcap_records(data)
    at = [r for r in records if r[1] == CHUNK_OPS[kind]][1][0]
    junk = random.Random(1).randbytes(8 << 20)
    damaged = data[:at] + junk + data[at:]
    damaged = _unindexed(damaged) if kind == "bag" else _unfinished(damaged)
    tracemalloc.start()
    try:
        got, losses = _read(tmp_path, f"g.{kind}", damaged)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert got == INTACT and losses >= 1
    assert peak < 24 << 20


def test_run_maps_a_log_with_a_garbage_chunk_header_and_records_the_loss(
    tmp_path: Path,
) -> None:
    intact_out, out = tmp_path / "intact", tmp_path / "out"
    assert CliRunner().invoke(app, ["run", str(BAG), "-o", str(intact_out), "-q"]).exit_code == 0
    data = BAG.read_bytes()
    third = [r for r in _ros1_records(data) if r[1] == 0x05][2]
    log = tmp_path / "damaged.bag"
    log.write_bytes(_unindexed(_garbage(data, third[0], 200)))
    res = CliRunner().invoke(app, ["run", str(log), "-o", str(out), "-q"])
    assert res.exit_code == 0, res.output  # far more than 1 % of the readings mapped
    m = json.loads((out / "metrics.json").read_text())
    full = json.loads((intact_out / "metrics.json").read_text())
    assert m["counts"]["readings"] > 0.8 * full["counts"]["readings"]
    assert m["input"]["bytes_lost"] >= third[2]
    assert any("skipped to the next record" in w for w in m["input"]["losses"])
    assert any(w.startswith("data lost:") for w in m["warnings"])


def test_a_damaged_page_of_a_rosbag2_database_loses_its_rows_only(
    targets: dict[str, Target], tmp_path: Path,
) -> None:
    """sqlite: a b-tree page of the messages table zeroed; the rows sqlite can still read
    are read by id ranges (formats/ros/sqlite_salvage.py), the lost ones counted."""
    target = targets["ros2-db3"]
    data = target.valid_bytes()
    intact = _read_target(target, data, tmp_path / "intact")
    assert intact == (677, 0)  # topics + messages of the simulated run
    page = 4096
    for n in (11, 21, 41):
        damaged = data[: n * page] + bytes(256) + data[n * page + 256 :]
        got, losses = _read_target(target, damaged, tmp_path / f"p{n}")
        assert 600 < got < 677 and losses == 1
    with open_log(target.materialize(tmp_path / "d", damaged)) as reader:
        for _ in reader.batches():
            pass
        (loss,) = reader.info().losses
    assert loss.startswith("sim_db3.db3: database is damaged (database disk image is"
                           " malformed); the rest read row by row: ")
    assert loss.endswith(" rows sqlite cannot read are lost")


def _read_target(target: Target, data: bytes, work: Path) -> tuple[int, int]:
    return read_with_losses(target.materialize(work, data))


# Mutations the long fuzz (`make fuzz`) found defects with, kept as regressions.
FOUND_BY_FUZZ = [
    # a message record whose time field is damaged, in a chunk walked (a KeyError once)
    ("ros1-real-example-unsorted-chunks.bag",
     Mutation(kind="flip", offset=4334, bits=(32, 64, 128, 128, 1, 2, 64))),
    # a corrupt stamp puts a batch out of order beside an intact copy (the merge stalled)
    ("ros2-db3-beside-a-copy", Mutation(kind="flip", offset=139979, bits=(128, 4, 16, 32, 4))),
]


@pytest.mark.parametrize(("name", "mutation"), FOUND_BY_FUZZ)
def test_what_the_fuzz_found_reads_or_refuses_with_one_line(
    targets: dict[str, Target], tmp_path: Path, name: str, mutation: Mutation,
) -> None:
    outcome = check_mutation(targets[name], mutation, tmp_path)
    assert outcome.status in ("ok", "loss", "rejected"), outcome.detail
