"""Compile every mapper kernel into numba's on-disk cache: ``python -m pipeline.mapper.kernels.warm``.

``make setup`` runs it once after installing, so the first ``sonarmap run`` (``make demo``,
the test suite) loads compiled code instead of compiling; it prints how long compiling took.
A run without it compiles on first use instead, with the same results.
"""

from __future__ import annotations

import time

from pipeline.config import MapperConfig
from pipeline.mapper import make_mapper
from pipeline.mapper.synthetic import ring_scans, room_grid
from pipeline.methods import Method


def warm() -> float:
    """Map a few synthetic scans with every compiled path; returns the seconds it took."""
    t0 = time.perf_counter()
    scans = ring_scans(4)
    for method in Method:
        mapper = make_mapper(MapperConfig(method=method), room_grid(0.1))
        for index in range(mapper.passes):
            mapper.begin_pass(index)
            mapper.integrate_many(scans)
        mapper.snapshot()
    return time.perf_counter() - t0


if __name__ == "__main__":
    print(f"mapper kernels compiled (or loaded from numba's cache) in {warm():.1f} s")
