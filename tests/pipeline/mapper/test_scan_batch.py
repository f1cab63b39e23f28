"""A batch of scans stored as one (ScanBatch): its scans and slices are views of its joined
readings, and joining a slice of it gives what joining the scans one by one gives."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.mapper.scan_group import concat_scans
from pipeline.mapper.types import SCAN_FIELDS, Scan, ScanBatch


def _scans(sizes: list[int]) -> list[Scan]:
    out, t = [], 0
    for n in sizes:
        col = np.arange(t, t + n, dtype=np.float64)
        out.append(Scan(np.arange(t, t + n, dtype=np.int64), np.zeros(n, np.int32),
                        *[col + k for k in range(7)]))
        t += n
    return out


def _batch(scans: list[Scan]) -> ScanBatch:
    cat, bounds = concat_scans(scans)
    return ScanBatch(cat, bounds.tolist())


def _same(a: Scan, b: Scan) -> None:
    for name in SCAN_FIELDS:
        got, want = getattr(a, name), getattr(b, name)
        assert got.dtype == want.dtype
        np.testing.assert_array_equal(got, want, err_msg=name)


def test_a_batch_is_the_sequence_of_its_scans() -> None:
    scans = _scans([3, 0, 5, 2])
    batch = _batch(scans)
    assert len(batch) == 4
    for got, want in zip(batch, scans, strict=True):
        _same(got, want)
    _same(batch[-1], scans[3])
    with pytest.raises(IndexError):
        batch[4]
    with pytest.raises(ValueError, match="step 1"):
        batch[::2]


def test_a_slice_joins_without_copying_as_the_scans_join() -> None:
    scans = _scans([3, 0, 5, 2, 4])
    batch = _batch(scans)
    for lo, hi in ((0, 5), (1, 4), (2, 3), (3, 3), (4, 9)):
        part = batch[lo:hi]
        assert isinstance(part, ScanBatch) and len(part) == len(scans[lo:hi])
        cat, bounds = concat_scans(part)
        want_cat, want_bounds = concat_scans(scans[lo:hi]) if scans[lo:hi] else (None, None)
        if want_cat is None:
            assert bounds.tolist() == [0] and len(cat) == 0
            continue
        assert bounds.tolist() == want_bounds.tolist()
        _same(cat, want_cat)
        assert np.shares_memory(cat.range_m, batch.cat.range_m) or len(cat) == 0
