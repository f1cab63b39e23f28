"""The kernels' pairwise sum (kernels/correction.py) equals numpy's ``np.sum`` bit for bit,
for every length the particle correction may use (blocks, one split, deeper splits)."""

from __future__ import annotations

import numpy as np

from pipeline.mapper.kernels.correction import pairwise_sum


def test_pairwise_sum_equals_numpy_bit_for_bit() -> None:
    rng = np.random.default_rng(21)
    # Values of mixed magnitude, so that a different summation order shows in the bits.
    a = rng.standard_normal(3000) * 10.0 ** rng.integers(-8, 8, 3000)
    lengths = [*range(0, 300), 383, 512, 777, 1024, 1500, 2049, 2990]
    for n in lengths:
        for lo in (0, 1, 7):
            want = np.sum(a[lo : lo + n])
            got = pairwise_sum(a, lo, n)
            assert np.float64(got).tobytes() == want.tobytes(), (n, lo)
