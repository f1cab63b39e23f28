"""The wall lines' compiled box moments (kernels.lines.line_moments) against numpy's."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.mapper.kernels.lines import line_moments
from pipeline.mapper.specular import box_sum


def numpy_moments(v: np.ndarray, psi: float, n: int) -> list[np.ndarray]:
    """The moments as numpy computes them: box sums of the weighted coordinates."""
    c, s = math.cos(psi), math.sin(psi)
    rows, cols = np.mgrid[0:v.shape[0], 0:v.shape[1]].astype(np.float64)
    on_n, on_t = cols * c + rows * s, rows * c - cols * s
    with np.errstate(invalid="ignore", divide="ignore"):
        m = box_sum(v, n)
        mn, mt = box_sum(v * on_n, n) / m, box_sum(v * on_t, n) / m
        var_n = box_sum(v * on_n * on_n, n) / m - mn * mn
        var_t = box_sum(v * on_t * on_t, n) / m - mt * mt
        cov = box_sum(v * on_n * on_t, n) / m - mn * mt
        cells = box_sum((v > 0).astype(np.float64), n)
    return [m, mn, var_n, var_t, cov, cells, np.abs(on_n - mn)]


@pytest.mark.parametrize(("shape", "n", "psi"), [((76, 76), 6, 0.1745), ((23, 41), 3, 2.9),
                                                 ((5, 30), 4, 1.5708)])
def test_line_moments_are_numpys_bit_for_bit(shape: tuple[int, int], n: int, psi: float) -> None:
    rng = np.random.default_rng(7)
    v = np.where(rng.random(shape) < 0.2, rng.integers(1, 900, shape), 0).astype(np.float64)
    v[:, : shape[1] // 3] = 0.0  # empty boxes too: 0/0 gives NaN moments in both
    got = line_moments(v, math.cos(psi), math.sin(psi), n)
    want = numpy_moments(v, psi, n)
    assert len(got) == 7
    for g, w in zip(got, want, strict=True):
        assert g.shape == shape
        assert g.tobytes() == w.tobytes()
    assert np.isnan(got[1]).any() and (got[0] > 0).any()
