"""Independent evaluations of the calibration search run on parallel threads.

numpy (large array operations) and the ``nogil`` numba kernels
(:mod:`pipeline.refine.kernels`) release the GIL, so candidate calibrations evaluate
side by side: 1.6-1.9× on two cores for the surface fits. Each evaluation is pure (it
reads shared arrays, writes only its own), so the results — and every decision taken on
them, in their given order — do not depend on the threads.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

from pipeline.cores import usable_cores

T = TypeVar("T")
R = TypeVar("R")


def parallel_map(fn: Callable[[T], R], items: Sequence[T]) -> list[R]:
    """``[fn(item) for item in items]``, on up to one thread per usable core."""
    workers = min(len(items), usable_cores())
    if workers <= 1:
        return [fn(item) for item in items]
    with ThreadPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(fn, items))
