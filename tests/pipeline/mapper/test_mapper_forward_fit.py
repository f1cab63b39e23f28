"""The detection fit's arithmetic (pipeline.mapper.forward): the in-place, column-summed
form gives the fit the expression written out gives, bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import ndtr

from pipeline.mapper.forward import (
    FIT_FLOOR,
    FIT_HEAD_ON,
    FIT_MEDIAN_DEG,
    FIT_SPREAD,
    INCIDENCE_BINS,
    fit_detection,
    last_axis_sum,
)


def fit_written_out(stats: np.ndarray) -> tuple[float, float, float, float]:
    """The fit as the model reads (numpy expressions, ``sum`` along the bins)."""
    centres = (np.arange(INCIDENCE_BINS) + 0.5) * (90.0 / INCIDENCE_BINS)
    z = (np.log(centres)[None, None, :] - np.log(FIT_MEDIAN_DEG)[:, None, None]) / FIT_SPREAD[
        None, :, None]
    vis = 1.0 - ndtr(z)
    a, n = stats[0, :INCIDENCE_BINS], stats[0, :INCIDENCE_BINS] + stats[1, :INCIDENCE_BINS]
    best = (-math.inf, 1.0, 90.0, 1.0, 0.0)
    for f in FIT_FLOOR:
        for p0 in FIT_HEAD_ON:
            p = np.clip(f + (1.0 - f) * p0 * vis, 1e-6, 1.0 - 1e-6)
            ll = (a * np.log(p) + (n - a) * np.log1p(-p)).sum(axis=-1)
            k = int(np.argmax(ll))
            if ll.flat[k] > best[0]:
                i, j = np.unravel_index(k, ll.shape)
                best = (float(ll.flat[k]), float(p0), float(FIT_MEDIAN_DEG[i]),
                        float(FIT_SPREAD[j]), float(f))
    return best[1], best[2], best[3], best[4]


@pytest.mark.parametrize("n", [3, 8, 9, 15, 16, 17, 40, 128, 129])
def test_last_axis_sum_is_numpys_sum_bit_for_bit(n: int) -> None:
    rng = np.random.default_rng(n)
    # magnitudes over 16 decades: any other order of the adds rounds differently
    t = rng.standard_normal((96, 14, n)) * 10.0 ** rng.integers(-8, 8, (96, 14, n))
    got = last_axis_sum(t)
    assert got.shape == (96, 14)
    assert got.tobytes() == t.sum(axis=-1).tobytes()


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_fit_detection_is_the_fit_written_out(seed: int) -> None:
    rng = np.random.default_rng(seed)
    scale = 10 ** (seed + 2)
    stats = np.zeros((2, INCIDENCE_BINS + 1))
    stats[0] = rng.integers(0, scale, INCIDENCE_BINS + 1)
    stats[1] = rng.integers(0, 3 * scale, INCIDENCE_BINS + 1)
    assert fit_detection(stats) == fit_written_out(stats)
