"""The scans of the first mapping pass, spilled and streamed back for the later passes: the
same values, dtypes and batches as built, and a multi-pass run from them writes the bytes
of a run that builds its scans again in every pass (one thread or two)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

import pipeline.run as run_module
from formats import open_log
from pipeline.config import Config, config_from_dict
from pipeline.mapper.scan_group import concat_scans
from pipeline.mapper.types import SCAN_FIELDS, Scan, ScanBatch
from pipeline.run import prepare, run, stream_scans
from pipeline.streaming.scan_spill import ScanSpill

OFFICE = Path(__file__).resolve().parents[3] / "sample_logs" / "office" / "office.mcap"


def _scan(n: int, seed: int) -> Scan:
    rng = np.random.default_rng(seed)
    return Scan(
        t_ns=np.arange(n, dtype=np.int64) * 1000 + seed,
        sensor_id=rng.integers(0, 16, n).astype(np.int32),
        range_m=np.where(rng.random(n) < 0.2, np.inf, rng.uniform(0.1, 5.0, n)),
        origin_x=rng.normal(size=n), origin_y=rng.normal(size=n), alpha=rng.uniform(-3, 3, n),
        fov=np.full(n, 0.5), min_range=np.full(n, 0.1), max_range=np.full(n, np.nan),
    )


def _assert_same_batches(got: Sequence[tuple[Sequence[Scan], int]],
                         want: Sequence[tuple[Sequence[Scan], int]]) -> None:
    assert [(len(s), seen) for s, seen in got] == [(len(s), seen) for s, seen in want]
    for (g_scans, _), (w_scans, _) in zip(got, want, strict=True):
        for g, w in zip(g_scans, w_scans, strict=True):
            for name in SCAN_FIELDS:
                a, b = getattr(g, name), getattr(w, name)
                assert a.dtype == b.dtype, name
                np.testing.assert_array_equal(a, b, err_msg=name)  # NaN, inf included


def test_spilled_batches_come_back_as_added_empty_ones_included() -> None:
    batches = [([_scan(5, 1), _scan(3, 2)], 8), ([], 9), ([_scan(1, 3)], 12),
               ([_scan(0, 4), _scan(7, 5)], 20), ([], 20)]
    spill = ScanSpill()
    for scans, seen in batches:
        spill.add(scans, seen)
    spilled = spill.finish()
    assert len(spilled) == 5  # scans
    first = list(spilled.batches())
    _assert_same_batches(first, batches)
    _assert_same_batches(list(spilled.batches()), batches)  # every pass walks it again
    scan = first[0][0][1]
    scan.range_m[0] = -1.0  # copies, writable as built scans are; the spill is unchanged
    # A batch's groups are its readings joined already: slices of one copy.
    group = first[3][0][0:2]
    cat, bounds = concat_scans(group)
    assert bounds.tolist() == [0, 0, 7]
    np.testing.assert_array_equal(cat.alpha, batches[3][0][1].alpha)
    assert np.shares_memory(cat.alpha, first[3][0].cat.alpha)
    assert next(iter(spilled.batches()))[0][1].range_m[0] == batches[0][0][1].range_m[0]


def test_a_batch_of_scans_spills_as_its_scans_do() -> None:
    # pass 0 hands the spill each chunk's scans as one ScanBatch (views of one join)
    lists = [([_scan(5, 1), _scan(3, 2)], 8), ([], 9), ([_scan(0, 4), _scan(7, 5)], 20)]
    spill = ScanSpill()
    for scans, seen in lists:
        cat, bounds = concat_scans(scans) if scans else (_scan(0, 0), np.zeros(1, np.int64))
        spill.add(ScanBatch(cat, bounds.tolist()), seen)
    got = list(spill.finish().batches())
    _assert_same_batches(got, lists)
    assert [b.bounds for b, _ in got] == [[0, 5, 8], [0], [0, 0, 7]]


def test_an_empty_spill_streams_its_empty_batches() -> None:
    spill = ScanSpill()
    spill.add([], 0)
    spilled = spill.finish()
    assert len(spilled) == 0
    assert [(list(s), seen) for s, seen in spilled.batches()] == [([], 0)]
    ScanSpill().close()  # a pass that failed: the files go


def test_the_office_scans_come_back_as_pose_sync_built_them() -> None:
    config = Config()
    with open_log(OFFICE, config) as reader:
        sv, sensors, grid = prepare(reader, config)
        built: list[tuple[list[Scan], int]] = []
        spill = ScanSpill()
        state = stream_scans(reader, sv, sensors, grid, config,
                             lambda scans: built.append((scans, 0)), spill=spill)
    spilled = list(spill.finish().batches())
    assert len(spilled) == len(built) and sum(len(s) for s, _ in built) == state.scans > 100
    assert spilled[-1][1] == state.readings_seen
    _assert_same_batches([(s, 0) for s, _ in spilled], built)


def _outputs(tmp: Path, name: str, threads: int) -> dict[str, bytes | dict[str, object]]:
    config = config_from_dict({"mapper": {"threads": threads}})
    out = tmp / name
    run(OFFICE, out, config)
    metrics = json.loads((out / "metrics.json").read_text())
    metrics.pop("timing")
    return {"map.pgm": (out / "map.pgm").read_bytes(),
            "features.parquet": (out / "features.parquet").read_bytes(),
            "metrics": metrics}


class _NoSpill(ScanSpill):
    """Every pass builds its scans from the readings again (as before the spill)."""

    def finish(self) -> None:  # type: ignore[override]
        self.close()


@pytest.mark.slow
def test_a_run_from_the_spilled_scans_writes_the_bytes_of_a_run_without(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    spilled = _outputs(tmp_path, "spilled", 2)
    assert spilled == _outputs(tmp_path, "one_thread", 1)
    monkeypatch.setattr(run_module, "ScanSpill", _NoSpill)
    assert spilled == _outputs(tmp_path, "rebuilt", 2)
