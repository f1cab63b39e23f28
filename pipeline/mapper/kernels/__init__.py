"""Compiled kernels (numba, ``@njit(cache=True)``) for the mapper's per-scan and per-reading loops.

Each module sits beside the numpy code it replaces, which stays as the readable reference
the tests compare it with (``tests/pipeline/mapper/test_kernels_*``):

* :mod:`.cone` — a sonar cone (annular sector) as row spans, one reading at a time; the
  cell rule of :func:`pipeline.mapper.grid_raster.sector_spans`; every mapper's cones
  (the attribution method's loops, :mod:`pipeline.mapper.kernels.attribution`, use it too).
* :mod:`.ellipse` — covariance ellipses as row spans; the occupied layer (§5).
* :mod:`.free_space` — a scan's free-space scan as a window mask; the free-layer update.
* :mod:`.free_unions` — a group's free-space scans packed, and their free-layer update
  (scan-local: the default method computes them on its feeding thread).
* :mod:`.feature_index` — the feature set's storage, hash grid and Kalman merge (§2).
* :mod:`.correction` — the touched test and the particle correction (§4).
* :mod:`.normals` — numpy's PCG64 and ziggurat inlined: the particles' normals, the same
  numbers as ``Generator.standard_normal``.
* :mod:`.andersone_scans` — the per-scan loop of the andersone mapper (§6 order).
* :mod:`.warm` — compiles everything into the cache (``make setup`` runs it).

The kernels give the same results as the numpy reference bit for bit: same arithmetic in
the same order, numpy's pairwise sums, the particle normals drawn from the same
``numpy.random.Generator``'s state with numpy's algorithms (:mod:`.normals`).

Compilation is cached on disk (``cache=True``): only the first run on a machine (or after
a kernel's source changes) compiles; :mod:`.cache_dir` picks a writable cache directory
before numba is imported (``NUMBA_CACHE_DIR`` wins when set).
"""

from __future__ import annotations

from pipeline.mapper.kernels.cache_dir import configure_cache_dir

configure_cache_dir()
