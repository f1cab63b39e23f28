"""Compile every kernel (the mappers' and pose refinement's) into numba's on-disk cache:
``python -m pipeline.mapper.kernels.warm``.

``make setup`` runs it once after installing, so the first ``sonarmap run`` (``make demo``,
the test suite) loads compiled code instead of compiling; it prints how long compiling took.
A run without it compiles on first use instead, with the same results.
"""

from __future__ import annotations

import time

import numpy as np

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
    _warm_refinement()
    return time.perf_counter() - t0


def _warm_refinement() -> None:
    """The kernels of ``--refine-poses`` (numba compiles per argument types)."""
    from pipeline.refine.kernels import (
        binned_sharpness_placed,
        consistency_placed,
        correlation_grid,
        free_samples,
        normal_equations,
        poses_at,
        step_segments,
        structure_tensor_at,
    )

    none2, none1, cells = np.empty((0, 3)), np.empty(0), np.zeros(1, np.int64)
    binned_sharpness_placed(none1, none1, none1, none1, none2, none2, 0.1)
    consistency_placed(none1, none1, none1, none1, none2, none2, none1, none1,
                       np.linspace(0.0, 1.0, 3), 0.2, 0.1, 0.4, 1.0, 4, 1.0)
    poses_at(0.0, 0.0, *step_segments(0.0, none1, none1, none1, none1, cells), np.ones(1),
             np.zeros(1))
    structure_tensor_at(np.zeros((3, 3)), np.zeros((3, 3)), cells, cells, np.ones(3) / 3)
    free_samples(none1, none1, none2, none2, none1, none1, 0.2, 0.0, 0.0, 0.1, np.zeros((2, 2)))
    correlation_grid(np.zeros(2), 1, 1, none1, none1, 1, np.zeros(3), 0.0, 0.0, 0.05,
                     np.zeros(1), cells)
    normal_equations(np.zeros(2, np.int64), np.zeros(1, np.int64), np.ones(1), np.ones(1),
                     np.ones(1), 1)


if __name__ == "__main__":
    print(f"mapper kernels compiled (or loaded from numba's cache) in {warm():.1f} s")
