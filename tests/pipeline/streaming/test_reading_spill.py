"""The readings pass 1 spills stream as the very chunks a direct read of the log gives
(late and backwards counts included), for one file and for a recording in several files,
and mapping from them builds the same scans."""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import pytest

from formats import open_log
from formats.contract import Batch, PoseBatch, make_range_batch
from pipeline.config import Config
from pipeline.mapper.types import SCAN_FIELDS, Scan
from pipeline.run import prepare, stream_scans
from pipeline.stages.ingest import RangeChunk, ordered_ranges, survey

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "formats" / "ros"))
from benchmarks.log_parts import anything, before, split_mcap

OFFICE = Path(__file__).resolve().parents[3] / "sample_logs" / "office" / "office.mcap"
T0 = 1_700_000_000_000_000_000
S = 1_000_000_000
KEPT = ("t_ns", "sensor_id", "range_m", "fov_rad", "min_range_m", "max_range_m", "scan_id")


def _assert_same_chunks(got: list[RangeChunk], want: list[RangeChunk]) -> None:
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        assert (g.late, g.backwards) == (w.late, w.backwards)
        for name in KEPT:
            a, b = getattr(g.batch, name), getattr(w.batch, name)
            assert a.dtype == b.dtype, name
            np.testing.assert_array_equal(a, b, err_msg=name)


class _Log:
    """A reader of fixed batches (poses, then the range batches in log order); its
    callers take the kinds they asked for."""

    path = Path("synthetic.log")

    def __init__(self, batches: Sequence[Batch]) -> None:
        self._batches = batches
        self.sensor_names = ["a", "b", "c"]

    def batches(self, kinds: Sequence[str] = ("ranges", "poses", "mounts")) -> Iterator[Batch]:
        yield from self._batches


def _log_with_late_and_backwards_readings() -> _Log:
    t = np.arange(0, 40 * S, S // 10, dtype=np.int64) + T0
    poses = PoseBatch(t, np.zeros(t.size), np.zeros(t.size), np.zeros(t.size), "odom", "base")
    batches: list[Batch] = [poses]
    rng = np.random.default_rng(7)
    for k in range(30):
        stamps = T0 + k * S + np.sort(rng.integers(0, S, 40))
        sensors = rng.integers(0, 2, 40)
        if k == 12:
            stamps[5:9] -= 4 * S  # sensor stamps jumping back: dropped as backwards
        rows = make_range_batch(stamps, sensors, rng.uniform(0.2, 4.0, 40), 0.5, 0.1, 5.0)
        batches.append(rows)
        if k == 20:  # sensor c's first readings arrive 3 s behind the stream: late
            batches.append(make_range_batch(stamps[:6] - 3 * S, 2, 1.0, 0.5, 0.1, 5.0))
    return _Log(batches)


def test_spilled_chunks_are_the_direct_reads_with_late_and_backwards_readings() -> None:
    log = _log_with_late_and_backwards_readings()
    sv = survey(log, keep_readings=True)  # type: ignore[arg-type]
    assert sv.readings is not None
    direct = list(ordered_ranges(log))  # type: ignore[arg-type]
    assert sum(c.late for c in direct) == 6 and sum(c.backwards for c in direct) > 0
    spilled = list(sv.readings.chunks())
    _assert_same_chunks(spilled, direct)
    assert len(sv.readings) == sum(len(c.batch) for c in direct)
    assert sv.ranges.backwards == sum(c.backwards for c in direct)
    # Every mapping pass walks the spill again: the second walk gives the same chunks.
    _assert_same_chunks(list(sv.readings.chunks()), direct)
    with pytest.raises(ValueError):
        spilled[0].batch.range_m[0] = 0.0  # views of the read-only mapping
    # What the spill does not keep reads as a log without it.
    b = spilled[0].batch
    np.testing.assert_array_equal(b.record_t_ns, b.t_ns)
    assert np.isnan(b.variance).all()


def test_survey_without_keep_readings_spills_nothing() -> None:
    log = _log_with_late_and_backwards_readings()
    sv = survey(log)  # type: ignore[arg-type]
    assert sv.readings is None
    _assert_same_chunks(list(sv.ordered_ranges(log)),  # type: ignore[arg-type]
                        list(ordered_ranges(log)))  # type: ignore[arg-type]


def test_a_recording_in_several_files_spills_what_it_reads_directly(tmp_path: Path) -> None:
    """Two files overlapping in time (the second a whole copy): the duplicates are read
    once and the spill holds exactly the direct read's chunks."""
    first, whole = tmp_path / "a.mcap", tmp_path / "b.mcap"
    split_mcap(OFFICE, [(first, before(T0 + 40 * S))], chunk_size=16 * 1024)
    split_mcap(OFFICE, [(whole, anything())], chunk_size=16 * 1024)
    with open_log([first, whole]) as reader:
        sv = survey(reader, keep_readings=True)
        assert reader.info().duplicates_read_once > 0
        direct = list(ordered_ranges(reader))
    assert sv.readings is not None and len(direct) > 1
    _assert_same_chunks(list(sv.readings.chunks()), direct)
    assert len(sv.readings) == sv.ranges.count


def test_mapping_from_the_spill_builds_the_scans_of_the_direct_read() -> None:
    config = Config()
    with open_log(OFFICE, config) as reader:
        sv, sensors, grid = prepare(reader, config)
        assert sv.readings is not None
        runs = []
        for survey_used in (sv, dataclasses.replace(sv, readings=None)):
            scans: list[Scan] = []
            state = stream_scans(reader, survey_used, sensors, grid, config, scans.extend)
            sv.track.release_before(None)
            runs.append((scans, state))
    (spilled, s_state), (direct, d_state) = runs
    assert s_state == d_state and s_state.scans == len(direct) > 100
    for a, b in zip(spilled, direct, strict=True):
        for name in SCAN_FIELDS:
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
