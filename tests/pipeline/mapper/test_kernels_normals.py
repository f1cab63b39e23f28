"""The inlined PCG64 normals (kernels/normals.py) against numpy's ``Generator``: the same
numbers, bit for bit, and the same generator state after them."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.mapper.kernels.normals import fill_standard_normal, pcg64_words, set_pcg64_words

ZIGGURAT_R = 3.6541528853610087  # draws beyond it take the ziggurat's tail branch


@pytest.mark.parametrize("seed", [0, 7, 2**63 + 5])
def test_the_same_stream_and_state_as_numpy_in_chunks(seed: int) -> None:
    ref = np.random.Generator(np.random.PCG64(seed))
    mine = np.random.Generator(np.random.PCG64(seed))
    ref.integers(0, 10, 3, dtype=np.uint32)  # a buffered 32-bit half, kept as it is
    mine.integers(0, 10, 3, dtype=np.uint32)
    want = ref.standard_normal(2_000_000)
    got = []
    rng = np.random.default_rng(seed % 1000)
    done = 0
    while done < want.shape[0]:
        n = min(int(rng.integers(0, 300_000)), want.shape[0] - done)
        out = np.empty(n)
        words = pcg64_words(mine)
        fill_standard_normal(words, out)
        set_pcg64_words(mine, words)
        got.append(out)
        done += n
    z = np.concatenate(got)
    assert z.tobytes() == want.tobytes()
    assert np.count_nonzero(np.abs(z) > ZIGGURAT_R) > 300  # the tail branch ran
    assert mine.bit_generator.state == ref.bit_generator.state
    assert mine.standard_normal() == ref.standard_normal()


def test_other_bit_generators_are_refused() -> None:
    with pytest.raises(TypeError, match="PCG64"):
        pcg64_words(np.random.Generator(np.random.Philox(1)))
