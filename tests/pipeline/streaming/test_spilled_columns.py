"""Columns spilled to temporary files read back exactly, also after their pages are given
back, and read-only."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.streaming.spilled_columns import ColumnSpill


def test_columns_read_back_exactly_after_their_pages_are_released() -> None:
    rng = np.random.default_rng(3)
    parts = [(rng.integers(-2**62, 2**62, n), rng.normal(size=n).astype(np.float32))
             for n in (5000, 0, 1, 70_000)]
    spill = ColumnSpill([np.int64, np.float32], "sonarmap-test-")
    for a, b in parts:
        spill.append(a, b)
    cols = spill.finish()
    want_a = np.concatenate([a for a, _ in parts])
    want_b = np.concatenate([b for _, b in parts])
    a, b = cols.columns
    assert len(cols) == 75_001 and a.dtype == np.int64 and b.dtype == np.float32
    np.testing.assert_array_equal(a, want_a)
    np.testing.assert_array_equal(b, want_b)
    with pytest.raises(ValueError):
        a[0] = 1  # read-only
    cols.release_before(40_000)  # as a walk in row order does behind itself
    np.testing.assert_array_equal(a, want_a)
    cols.release_before(None)
    np.testing.assert_array_equal(b, want_b)


def test_an_empty_spill_gives_empty_columns_of_its_dtypes() -> None:
    cols = ColumnSpill([np.int32, np.float64], "sonarmap-test-").finish()
    assert len(cols) == 0
    assert [c.dtype for c in cols.columns] == [np.int32, np.float64]
    cols.release_before(10)
    cols.release_before(None)


def test_columns_of_different_lengths_are_refused() -> None:
    spill = ColumnSpill([np.int64, np.int64], "sonarmap-test-")
    with pytest.raises(ValueError, match="one length"):
        spill.append([1, 2], [3])
    spill.close()


def test_strided_columns_spill_their_values() -> None:
    base = np.arange(20, dtype=np.int64)
    spill = ColumnSpill([np.int64], "sonarmap-test-")
    spill.append(base[::2])  # a view with a stride: its values, not its buffer
    (col,) = spill.finish().columns
    np.testing.assert_array_equal(col, np.arange(0, 20, 2))
