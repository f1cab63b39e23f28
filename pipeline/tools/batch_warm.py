"""Batch workers warmed as the cluster starts: ``dask_setup`` for Dask's worker preload.

A process pays once what every run needs: the pipeline's imports, numba's first-call
set-up and the loading of the cached kernels (``mapper.kernels.warm``, which compiles them
when the cache is cold), the ROS type store of ``map.mcap``. ``sonarmap batch`` starts its
local workers with this preload (:data:`pipeline.tools.batch.WORKER_PRELOAD`), so each worker pays
that while the cluster starts, all workers at once, instead of in its first log; workers of
a cluster of one's own get it with ``dask worker --preload pipeline.tools.batch_warm``. What a
log's mapping gives does not depend on it.
"""

from __future__ import annotations

import logging

log = logging.getLogger("sonarmap.batch")


def dask_setup(worker: object) -> None:
    """Warm this process (Dask calls it in each worker before the worker registers).

    A failure is logged, not raised: the worker still starts, and its first log pays the
    warm-up (or fails as that log's row, with its own message)."""
    try:
        from formats.writers import map_mcap
        from pipeline import run  # noqa: F401  (the pipeline's imports)
        from pipeline.mapper.kernels.warm import warm

        warm()
        map_mcap.warm()
    except Exception as err:  # a worker that cannot warm up must still map (or fail) logs
        log.warning("batch worker warm-up failed: %s: %s", type(err).__name__, err)
