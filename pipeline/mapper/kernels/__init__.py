"""Compiled kernels (numba, ``@njit(cache=True)``) for the mapper's per-scan and per-reading loops.

Each module sits beside the numpy code it replaces, which stays as the readable reference
the tests compare it with (``tests/mapper/test_kernels_*``):

* :mod:`.cone` — a sonar cone (annular sector) as row spans, one reading at a time; the
  cell rule of :func:`pipeline.mapper.grid_raster.sector_spans`.

Compilation is cached on disk (``cache=True``): only the first run on a machine (or after
a kernel's source changes) compiles; :mod:`.cache_dir` picks a writable cache directory
before numba is imported (``NUMBA_CACHE_DIR`` wins when set).
"""

from __future__ import annotations

from pipeline.mapper.kernels.cache_dir import configure_cache_dir

configure_cache_dir()
