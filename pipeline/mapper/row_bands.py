"""A kernel's grid writes split between two threads by row band, with the same bytes.

A kernel that adds each reading's evidence to the cells of its cone, in reading order, can
run as two calls over the same readings: one writes only the rows ``0 ≤ r < split``, the
other ``split ≤ r < height`` (its ``row_lo, row_hi``). Every cell is then written by one
call only, which adds to it the same values in the same order as one call over all rows
would: the float sums are the same bits, whatever ``split`` is and whichever thread runs
first. The kernels release the GIL (``nogil``), so the two calls run on two cores.

:func:`balanced_split` puts ``split`` where the readings' cones hold about half their
cells (an estimate: it only balances the threads' work). :class:`RowBands` runs the upper
band on a worker thread of its own while the calling thread does the lower one; with one
thread it makes one call over all rows.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TypeVar

import numpy as np

from pipeline.mapper.types import F64

T = TypeVar("T")
# A cone's cells lie about this share of its radius out along its axis (the centroid of a
# sector of a narrow beam: 2/3).
CENTROID = 2.0 / 3.0


def balanced_split(cones: F64, alpha: F64, gy: float, res: float, height: int,
                   share: float = 0.5) -> int:
    """The row below which the cones hold the ``share`` of their estimated cells (a half:
    the median of their centroids' rows, each weighted by its area; ``cones`` as
    :func:`~pipeline.mapper.free_space.cone_table`)."""
    if cones.shape[0] == 0:
        return height // 2
    radius = cones[:, 2]
    row = (cones[:, 1] + CENTROID * radius * np.sin(alpha) - gy) / res
    weight = radius * radius
    order = np.argsort(row, kind="stable")
    cum = np.cumsum(weight[order])
    mid = int(np.searchsorted(cum, share * cum[-1]))
    return min(max(math.floor(row[order][min(mid, len(order) - 1)]), 0), height)


class RowBands:
    """Runs ``band(row_lo, row_hi)`` over two row bands on two threads (module doc)."""

    def __init__(self, threads: int) -> None:
        self._pool: ThreadPoolExecutor | None = None
        if threads > 1:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="sonarmap-band")
            weakref.finalize(self, self._pool.shutdown, wait=True)

    def run(self, band: Callable[[int, int], int], split: int, height: int) -> int:
        """``band(0, split) + band(split, height)``, the upper one on the worker thread."""
        if self._pool is None:
            return band(0, height)
        upper = self._pool.submit(band, split, height)
        try:
            lower = band(0, split)
        finally:
            total = upper.result()
        return lower + total

    @property
    def parallel(self) -> bool:
        """Whether a worker thread runs beside the calling thread."""
        return self._pool is not None

    def later(self, work: Callable[[], T]) -> Future[T]:
        """``work()`` on the worker thread (after the work handed to it before), or now on
        this thread with one thread; its result or error comes from the future."""
        if self._pool is not None:
            return self._pool.submit(work)
        done: Future[T] = Future()
        done.set_result(work())
        return done

    def close(self) -> None:
        """Stop the worker thread (the bands after run in one call on this thread)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
